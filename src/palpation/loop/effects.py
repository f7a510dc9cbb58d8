"""Candidate effects the residual loop can add to the twin: each a switch plus parameters, with nominal steps.

A *parameter* is one searched number of the twin, in the units of its config field (SI, except the
camera in px/deg and the mount in mm/deg), and says where it acts:
* ("env", key): a per-env parameter of `BatchedTwin` (k_s, k_t, mu, E, and with the layered kernel
  alpha and shell_ratio);
* ("camera", field): twin.camera, an image similarity applied at projection (see CameraConfig);
* ("mount", field): twin.mount, a rigid offset of the sensor from the commanded pose;
* ("markers", field): twin.markers, the marker model (anchor: the bound rest moved onto the template).

A *dof* is one signature column: the parameters it moves and by how much ("add" a step or "mul" by a
factor). An effect's signature at the current twin is the marker-field change of each dof at its
nominal step. Friction moves k_t and mu together (one column); the camera and the mount have one
column per degree of freedom because the data decide the mixture and the signs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np


@dataclass(frozen=True)
class Param:
    name: str
    unit: str
    low: float
    high: float
    log: bool
    target: tuple[str, str]  # ("env" | "camera" | "mount", key or field)
    scale: float = 1.0  # config value = value * scale (mount dz: mm -> m)
    default: float = 0.0  # value with the effect off


@dataclass(frozen=True)
class Dof:
    name: str
    moves: tuple[tuple[str, str, float], ...]  # (param, "add" | "mul", amount) at the nominal step
    nonneg: bool  # physical only in the +step direction (a contact stiffness cannot be negative)


@dataclass(frozen=True)
class Effect:
    name: str
    title: str
    params: tuple[str, ...]
    dofs: tuple[Dof, ...]


PARAMS: dict[str, Param] = {p.name: p for p in (
    Param("E", "Pa", 1.0e5, 2.0e6, True, ("env", "E"), default=881400.0),
    Param("k_s", "N/m per surface node", 1.0e2, 3.0e4, True, ("env", "k_s")),
    Param("k_t", "N s/m", 0.0, 200.0, False, ("env", "k_t")),
    Param("mu", "1", 0.0, 1.5, False, ("env", "mu")),
    Param("alpha", "N s/m", 2.0e-3, 1.5, True, ("env", "alpha"), default=0.02),
    Param("shell_ratio", "E_shell / E", 1.0, 4.0, True, ("env", "shell_ratio"), default=1.0),
    Param("cam_f_scale", "1", 0.85, 1.15, False, ("camera", "f_scale"), default=1.0),
    Param("cam_rotation_deg", "deg", -15.0, 15.0, False, ("camera", "rotation_deg")),
    Param("cam_dx_px", "px", -60.0, 60.0, False, ("camera", "dx_px")),
    Param("cam_dy_px", "px", -60.0, 60.0, False, ("camera", "dy_px")),
    Param("mount_dz_mm", "mm", -1.5, 1.5, False, ("mount", "dz"), scale=1e-3),
    Param("mount_tilt_x_deg", "deg", -6.0, 6.0, False, ("mount", "tilt_x_deg")),
    Param("mount_tilt_y_deg", "deg", -6.0, 6.0, False, ("mount", "tilt_y_deg")),
    Param("marker_anchor", "fraction of the rest offset", 0.0, 1.5, False, ("markers", "anchor")),
)}


def _dof(name, nonneg, *moves):
    return Dof(name, tuple(moves), nonneg)


EFFECTS: dict[str, Effect] = {e.name: e for e in (
    Effect("surface_contact", "sensor-phantom surface contact (k_s)", ("k_s",),
           (_dof("k_s", True, ("k_s", "add", 2.0e3)),)),
    Effect("friction", "tangential friction (k_t, mu)", ("k_t", "mu"),
           (_dof("friction", True, ("k_t", "add", 20.0), ("mu", "add", 0.5)),)),
    Effect("camera", "camera intrinsics error (f, principal point, image rotation)",
           ("cam_f_scale", "cam_rotation_deg", "cam_dx_px", "cam_dy_px"),
           (_dof("f_scale", False, ("cam_f_scale", "add", 0.05)),
            _dof("rotation", False, ("cam_rotation_deg", "add", 5.0)),
            _dof("dx", False, ("cam_dx_px", "add", 20.0)),
            _dof("dy", False, ("cam_dy_px", "add", 20.0)))),
    Effect("mount", "sensor mounting offset/tilt", ("mount_dz_mm", "mount_tilt_x_deg", "mount_tilt_y_deg"),
           (_dof("dz", False, ("mount_dz_mm", "add", 0.5)),
            _dof("tilt_x", False, ("mount_tilt_x_deg", "add", 2.0)),
            _dof("tilt_y", False, ("mount_tilt_y_deg", "add", 2.0)))),
    Effect("viscous", "rate-dependent (viscous) lag: damping alpha", ("alpha",),
           (_dof("alpha", False, ("alpha", "mul", 5.0)),)),
    Effect("layered", "layered skin: stiffer outer shell (E_shell / E)", ("shell_ratio",),
           (_dof("shell_ratio", True, ("shell_ratio", "add", 1.0)),)),
    Effect("marker_anchor", "marker binding offset: markers anchored at the rest template", ("marker_anchor",),
           (_dof("anchor", True, ("marker_anchor", "add", 0.5)),)),
)}


def check_effects(names, where: str = "loop.effects") -> list[str]:
    unknown = [n for n in names if n not in EFFECTS]
    if unknown:
        raise ValueError(f"{where}: unknown effect(s) {unknown}; known: {sorted(EFFECTS)}")
    return list(names)


def defaults(effects) -> dict[str, float]:
    """The values of every parameter of `effects` with the effects switched off."""
    return {p: PARAMS[p].default for e in effects for p in EFFECTS[e].params}


def move(params: Mapping[str, float], dof: Dof, beta: float = 1.0, overrides: Mapping[str, float] | None = None
         ) -> dict[str, float]:
    """`params` moved along a dof by beta nominal steps (add: + beta * step; mul: * factor ** beta)."""
    out = dict(params)
    for name, mode, amount in dof.moves:
        amount = (overrides or {}).get(name, amount)
        base = out.get(name, PARAMS[name].default)
        out[name] = base + beta * amount if mode == "add" else base * amount ** beta
    return out


def bounds(name: str, overrides: Mapping[str, Sequence[float]] | None = None) -> tuple[float, float]:
    """Search bounds of a parameter; `overrides` (loop.search.bounds) replace effects.py's per name."""
    if overrides and name in overrides:
        low, high = overrides[name]
        return float(low), float(high)
    return PARAMS[name].low, PARAMS[name].high


def clip(params: Mapping[str, float], overrides: Mapping[str, Sequence[float]] | None = None
         ) -> dict[str, float]:
    """Each parameter into its search bounds (a warm start from a linear estimate can overshoot)."""
    return {k: float(np.clip(v, *bounds(k, overrides))) if k in PARAMS else float(v) for k, v in params.items()}


def split(params: Mapping[str, float]) -> tuple[dict, dict, dict, dict]:
    """Loop parameters -> (env params for BatchedTwin, camera, mount, markers fields) in config units."""
    groups = {"env": {}, "camera": {}, "mount": {}, "markers": {}}
    for name, value in params.items():
        if name not in PARAMS:
            raise ValueError(f"unknown loop parameter '{name}'; known: {sorted(PARAMS)}")
        p = PARAMS[name]
        where, key = p.target
        groups[where][key] = float(value) * p.scale
    return groups["env"], groups["camera"], groups["mount"], groups["markers"]


def twin_overrides(params: Mapping[str, float], effects, shell_thickness_m: float) -> dict[str, dict]:
    """The TwinConfig sections and fields a loop result sets, switches included (for twin_fit/*.yaml)."""
    env, camera, mount, markers = split(params)
    section = {"E": ("material", "E"), "nu": ("material", "nu"), "k_s": ("contact", "k_s"),
               "k_t": ("contact", "k_t"), "mu": ("contact", "mu"), "alpha": ("damping", "alpha"),
               "shell_ratio": ("material", "shell_ratio")}
    out: dict[str, dict] = {}
    for key, value in env.items():
        sec, field = section[key]
        out.setdefault(sec, {})[field] = value
    if camera:
        out["camera"] = camera
    if mount:
        out["mount"] = mount
    if markers:
        out["markers"] = markers
    if "surface_contact" in effects or "friction" in effects:
        out.setdefault("contact", {})["phantom_contact"] = True
    if "layered" in effects:
        out.setdefault("material", {})["shell_thickness"] = float(shell_thickness_m)
    return out
