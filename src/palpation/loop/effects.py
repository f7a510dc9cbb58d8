"""Candidate effects the residual loop can add to the twin: each a switch plus parameters, with nominal steps.

Both come from the twin's parameter registry (twin.parameters): an entry with a `LoopStep` belongs to
an effect of EFFECT_TITLES and carries its nominal step, so a new effect is a registry entry, not code
here.

A *parameter* is an entry of the twin's registry (twin.parameters: unit, bounds, log scale, default,
dependencies); the loop searches E and the parameters its effects name. Each acts:
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

from palpation.twin.config import TwinConfig
from palpation.twin.parameters import EFFECT_REQUIRES, EFFECT_TITLES, PARAMETERS, TwinParameter, by_env_key


@dataclass(frozen=True)
class Param:
    """A twin parameter as the loop searches it (read from twin.parameters, never restated)."""

    name: str
    unit: str
    low: float
    high: float
    log: bool
    target: tuple[str, str]  # ("env" | "camera" | "mount" | "markers", key or field)
    scale: float = 1.0  # config value = value * scale (mount dz: mm -> m)
    default: float = 0.0  # value with the effect off

    @classmethod
    def of(cls, p: TwinParameter) -> "Param":
        return cls(p.name, p.unit, p.low, p.high, p.log, ("env" if p.per_env else p.section, p.field), p.scale,
                   p.off_value(TwinConfig()))


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
    requires: tuple[str, ...] = ()  # effects it acts through (twin.parameters.EFFECT_REQUIRES)


def _effect(name: str, title: str) -> Effect:
    """An effect from its registry entries (twin.parameters: LoopStep), dofs in registry order."""
    entries = [p for p in PARAMETERS.values() if p.loop is not None and p.loop.effect == name]
    if not entries:
        raise ValueError(f"loop effect '{name}' has no parameter in palpation/twin/parameters.py (LoopStep)")
    dofs: dict[str, list] = {}
    for p in entries:
        dofs.setdefault(p.loop.dof, []).append(p)
    return Effect(name, title, tuple(p.name for p in entries),
                  tuple(Dof(d, tuple((p.name, p.loop.mode, p.loop.amount) for p in ps), ps[0].loop.nonneg)
                        for d, ps in dofs.items()), tuple(EFFECT_REQUIRES.get(name, ())))


_stray = {p.loop.effect for p in PARAMETERS.values() if p.loop is not None} - set(EFFECT_TITLES)
if _stray:
    raise ValueError(f"twin.parameters: LoopStep effect(s) {sorted(_stray)} missing from EFFECT_TITLES")
EFFECTS: dict[str, Effect] = {name: _effect(name, title) for name, title in EFFECT_TITLES.items()}


def _check_requires() -> None:
    """EFFECT_REQUIRES must match the registry: an effect whose parameters need contact requires the effect
    that switches contact on (a parameter needing the phantom with an 'off' value), and nothing else."""
    providers = {p.loop.effect for p in PARAMETERS.values() if p.loop and p.needs == "phantom" and p.off is not None}
    for name, eff in EFFECTS.items():
        needs = {PARAMETERS[n].needs for n in eff.params}
        want = set() if name in providers or not needs & {"contact", "phantom"} else providers
        if set(eff.requires) != want:
            raise ValueError(f"twin.parameters.EFFECT_REQUIRES['{name}'] = {sorted(eff.requires)}, but its "
                             f"parameters need {sorted(needs)}: it should be {sorted(want)}")


_check_requires()

# the loop's parameters: E (searched every round, loop.recalibrate) and every effect's, in registry order
LOOP_PARAMS = {"E", *(n for e in EFFECTS.values() for n in e.params)}
PARAMS: dict[str, Param] = {n: Param.of(p) for n, p in PARAMETERS.items() if n in LOOP_PARAMS}


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


def strength(effect: str, params: Mapping[str, float]) -> float:
    """How far `params` hold `effect` from off, in nominal steps (move's inverse): over its dofs, the root sum of
    squares of each dof's largest |beta| among the parameters it moves."""
    total = 0.0
    for dof in EFFECTS[effect].dofs:
        beta = 0.0
        for name, mode, amount in dof.moves:
            off, value = PARAMS[name].default, params.get(name, PARAMS[name].default)
            if mode == "add":
                beta = max(beta, abs(value - off) / amount)
            elif value > 0 and off > 0:
                beta = max(beta, abs(np.log(value / off) / np.log(amount)))
            elif value != off:
                beta = float("inf")
        total += beta * beta
    return float(np.sqrt(total))


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
    out: dict[str, dict] = {}
    for key, value in env.items():
        p = by_env_key(key)
        out.setdefault(p.section, {})[p.field] = value
    if camera:
        out["camera"] = camera
    if mount:
        out["mount"] = mount
    if markers:
        out["markers"] = markers
    needs = {PARAMETERS[n].needs for e in effects for n in EFFECTS[e].params}  # the switches they act through
    if needs & {"phantom", "contact"}:  # no vessel in the loop's states: contact means the phantom
        out.setdefault("contact", {})["phantom_contact"] = True
    if "shell" in needs:
        out.setdefault("material", {})["shell_thickness"] = float(shell_thickness_m)
    return out
