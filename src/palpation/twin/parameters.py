"""The one registry of the twin's physical parameters: name, unit, where it acts, bounds, dependencies.

Every module that names a twin parameter reads it from here: `BatchedTwin.set_env_params` (which keys
it takes per env and their config defaults), `runner.EnvRequest` (what a request may set), the
calibration's search space (calibration.params) and the residual loop's parameters (loop.effects).
Adding a per-env parameter is one entry below, its config field (twin.config) and the kernel that
reads it; an entry with a `LoopStep` is also a residual-loop effect (docs/ARCHITECTURE.md).

An entry's value is in its `unit`; the config field holds value * scale (only the mount's dz, kept in
mm, and the reference-unit aliases scale). Defaults are never restated: `default(cfg)` reads the
config field. Bounds are the physical search range (the loop searches and clips within them, a
calibration takes them where its config leaves a range out and warns when its range leaves them), not
validity limits: the simulator itself refuses non-physical values (`env_values`, `layered_values` check the per-env
arrays it takes).

scope: "env"      per env in every twin (a BatchedTwin array, read by the force kernels);
       "layered"  per env only with the layered elastic kernel (twin.layered), else the config's value;
       "camera" | "mount" | "markers": one TwinConfig value for a batch, applied at projection / to the
                  commanded pose; the loop varies them per env itself (loop.simulate).
needs: what must be on for the parameter to act: "vessel" (the per-env vessel switch), "phantom"
       (contact.phantom_contact), "contact" (either of them), "shell" (material.shell_thickness > 0).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from palpation import paper


@dataclass(frozen=True)
class LoopStep:
    """How the residual loop adds a parameter to the twin (loop.effects builds its effects from these)."""

    effect: str  # the candidate effect it belongs to (EFFECT_TITLES)
    dof: str  # its signature column; entries of one effect with the same dof move together
    amount: float  # the nominal step
    mode: str = "add"  # add: + amount; mul: x amount
    nonneg: bool = False  # physical only in the +step direction (a stiffness cannot go negative)


# the residual loop's candidate effects, in the order it tries them by default (loop.config)
EFFECT_TITLES = {
    "surface_contact": "sensor-phantom surface contact (k_s)",
    "friction": "tangential friction (k_t, mu)",
    "camera": "camera intrinsics error (f, principal point, image rotation)",
    "mount": "sensor mounting offset/tilt",
    "viscous": "rate-dependent (viscous) lag: damping alpha",
    "layered": "layered skin: stiffer outer shell (E_shell / E)",
    "marker_anchor": "marker binding offset: markers anchored at the rest template",
}
# effects that act only through another one (their parameters `need` a switch that effect turns on): friction
# touches nothing until the sensor touches the phantom, so without surface contact its signature is dead and
# the loop can only find it together with it (loop.engine tries such pairs jointly). loop.effects checks this
# against the `needs` of the entries below. The mount is not one: without contact it still moves the markers
# through the dome's inertia (the self-test measured it explaining 95 % of a viscous residual with no contact).
EFFECT_REQUIRES = {
    "friction": ("surface_contact",),
}


@dataclass(frozen=True)
class TwinParameter:
    name: str  # as BatchedTwin, EnvRequest, conf/calibration and the loop write it
    unit: str
    section: str  # TwinConfig section holding its default
    field: str  # field in that section; also the BatchedTwin env key of a per-env parameter
    scope: str  # env | layered | camera | mount | markers (module docstring)
    kernel: str  # where the physics reads it
    low: float  # physical search bounds, in `unit`
    high: float
    log: bool  # searched on a log scale
    why: str  # where the bounds come from
    needs: str = ""  # vessel | phantom | contact | shell | "" (module docstring)
    scale: float = 1.0  # config value = value * scale
    off: float | None = None  # value that switches the effect off when the config default does not
    loop: LoopStep | None = None  # the residual loop's effect and nominal step; None: not a loop effect

    @property
    def per_env(self) -> bool:
        return self.scope in ("env", "layered")

    def default(self, cfg) -> float:
        """The value in a TwinConfig (in this entry's unit)."""
        value = getattr(getattr(cfg, self.section), self.field)
        return value / self.scale if self.scale != 1.0 else value

    def off_value(self, cfg) -> float:
        """The value at which the parameter adds nothing to `cfg`'s twin (the loop's starting point)."""
        return self.default(cfg) if self.off is None else self.off


_ELASTIC = "twin.elasticity (elastic force)"
CONTACT_KERNEL = "twin.contact (node contact force; a ContactParams array)"  # simulator fills these arrays
PARAMETERS: dict[str, TwinParameter] = {p.name: p for p in (
    TwinParameter("E", "Pa", "material", "E", "env", _ELASTIC, 1.0e5, 2.0e6, True,
                  "SPEC §6.3 searched [1e5, 1e6]; with surface contact the photos move E to ~1.2e6"),
    TwinParameter("nu", "1", "material", "nu", "env", _ELASTIC, 0.30, 0.499, False,
                  "silicone is near-incompressible; lambda diverges at 0.5 (SPEC §2.3: 0.497)"),
    TwinParameter("k_n", "N/m (physical)", "contact", "k_n", "env", CONTACT_KERNEL, 1.0e3, 2.0e4, True,
                  "SPEC §6.3 search [1e4, 1e5] and §7 draw [5e3, 5e4] in reference units, / 5",
                  needs="vessel"),
    TwinParameter("c_n", "N s/m^2 (x depth, quirk 11)", "contact", "c_n", "env", CONTACT_KERNEL, 0.0, 200.0, False,
                  "SPEC §7 draws U(0, 100); twice the calibrated 100", needs="vessel"),
    TwinParameter("k_s", "N/m per surface node", "contact", "k_s", "env", CONTACT_KERNEL, 1.0e2, 3.0e4, True,
                  "from barely touching to stiffer than the 2e4 default", needs="phantom", off=0.0,
                  loop=LoopStep("surface_contact", "k_s", 2.0e3, nonneg=True)),
    TwinParameter("c_s", "N s/m^2", "contact", "c_s", "env", CONTACT_KERNEL, 0.0, 200.0, False,
                  "same form and range as c_n", needs="phantom"),
    TwinParameter("k_t", "N s/m", "contact", "k_t", "env", CONTACT_KERNEL, 0.0, 200.0, False,
                  "viscous tangential stiffness, from none (the reference) up", needs="contact",
                  loop=LoopStep("friction", "friction", 20.0, nonneg=True)),
    TwinParameter("mu", "1", "contact", "mu", "env", CONTACT_KERNEL, 0.0, 1.5, False,
                  "Coulomb coefficient, from none (the reference) to 1.5", needs="contact",
                  loop=LoopStep("friction", "friction", 0.5, nonneg=True)),
    # compliant phantom with vessel inclusions (issue 12; docs/slides.md): contact.phantom_model=foundation
    TwinParameter("k_f", "N/m^3 (pressure per penetration)", "contact", "k_f", "env", CONTACT_KERNEL, 1.0e6, 2.0e8,
                  True, "Winkler modulus E/H: silicone E 30 kPa - 1 MPa over a 5-30 mm column", needs="phantom"),
    TwinParameter("incl_ratio", "E_vessel / E_phantom", "contact", "incl_ratio", "env", CONTACT_KERNEL, 1.0, 100.0,
                  True, "1 = no vessel; a silicone tube in soft silicone up to ~100x", needs="phantom", off=1.0),
    TwinParameter("incl_depth", "m", "contact", "incl_depth", "env", CONTACT_KERNEL, 1.0e-3, 8.0e-3, False,
                  "axis depth of a vessel visible from the top (SPEC §3.1: 3 mm); not recorded for the phantom",
                  needs="phantom"),
    TwinParameter("incl_diameter", "m", "contact", "incl_diameter", "env", CONTACT_KERNEL, 2.0e-3, 8.0e-3, False,
                  "SPEC §13.6 radius ~2 mm; the photo's polygons 4.4-4.9 mm wide", needs="phantom"),
    TwinParameter("alpha", "N s/m", "damping", "alpha", "layered", "twin.elasticity (layered kernel damping)",
                  2.0e-3, 1.5, True, "0.1x to 75x the reference-equivalent 0.02 (SPEC §2.3)",
                  loop=LoopStep("viscous", "alpha", 5.0, mode="mul")),
    TwinParameter("shell_ratio", "E_shell / E", "material", "shell_ratio", "layered",
                  "twin.elasticity (layered kernel modulus)", 1.0, 4.0, True,
                  "a stiffer outer skin only, up to 4x", needs="shell",
                  loop=LoopStep("layered", "shell_ratio", 1.0, nonneg=True)),
    TwinParameter("cam_f_scale", "1", "camera", "f_scale", "camera", "twin.markers (image similarity)",
                  0.85, 1.15, False, "+-15 % focal length", loop=LoopStep("camera", "f_scale", 0.05)),
    TwinParameter("cam_rotation_deg", "deg", "camera", "rotation_deg", "camera", "twin.markers (image similarity)",
                  -15.0, 15.0, False, "image rotation about the principal point",
                  loop=LoopStep("camera", "rotation", 5.0)),
    TwinParameter("cam_dx_px", "px", "camera", "dx_px", "camera", "twin.markers (image similarity)",
                  -60.0, 60.0, False, "principal point shift, about one marker spacing (55 px)",
                  loop=LoopStep("camera", "dx", 20.0)),
    TwinParameter("cam_dy_px", "px", "camera", "dy_px", "camera", "twin.markers (image similarity)",
                  -60.0, 60.0, False, "principal point shift, about one marker spacing (55 px)",
                  loop=LoopStep("camera", "dy", 20.0)),
    TwinParameter("mount_dz_mm", "mm", "mount", "dz", "mount", "twin.trajectory (mount offset)",
                  -1.5, 1.5, False, "depth offset of a hand-set mount, +-1.5 mm", scale=1e-3,
                  loop=LoopStep("mount", "dz", 0.5)),
    TwinParameter("mount_tilt_x_deg", "deg", "mount", "tilt_x_deg", "mount", "twin.trajectory (mount offset)",
                  -6.0, 6.0, False, "mounting tilt", loop=LoopStep("mount", "tilt_x", 2.0)),
    TwinParameter("mount_tilt_y_deg", "deg", "mount", "tilt_y_deg", "mount", "twin.trajectory (mount offset)",
                  -6.0, 6.0, False, "mounting tilt", loop=LoopStep("mount", "tilt_y", 2.0)),
    TwinParameter("marker_anchor", "fraction of the rest offset", "markers", "anchor", "markers",
                  "twin.runner / loop.simulate (marker shift)", 0.0, 1.5, False,
                  "1 puts the rest markers on the template; a little past it",
                  loop=LoopStep("marker_anchor", "anchor", 0.5, nonneg=True)),
)}


def _in_reference_units(p: TwinParameter) -> TwinParameter:
    """A contact stiffness as the reference writes it (x5 length): twin value = reference value / 5."""
    s = paper.LENGTH_SCALE
    return replace(p, name=f"{p.name}_ref", unit=f"reference units (x5 length); twin {p.field} = {p.name}_ref / 5",
                   low=p.low * s, high=p.high * s, scale=p.scale / s, why=p.why + " (reference units)")


# other names of a per-env parameter, in the units a source quotes (SPEC's k_n = 94,908 reference units)
ALIASES: dict[str, TwinParameter] = {a.name: a for a in map(_in_reference_units, (PARAMETERS["k_n"],
                                                                                  PARAMETERS["k_t"]))}


ENV_KEYS = tuple(p.field for p in PARAMETERS.values() if p.scope == "env")  # BatchedTwin env keys
LAYERED_KEYS = tuple(p.field for p in PARAMETERS.values() if p.scope == "layered")  # ... with cfg.layered
CONTACT_KEYS = tuple(p.field for p in PARAMETERS.values() if p.per_env and p.kernel == CONTACT_KERNEL)


def per_env_keys(layered: bool = True) -> tuple[str, ...]:
    """The BatchedTwin env keys besides the vessel switch (scope env, and with `layered` scope layered)."""
    return ENV_KEYS + LAYERED_KEYS if layered else ENV_KEYS


def by_env_key(key: str) -> TwinParameter:
    """The registry entry of a BatchedTwin env key."""
    for p in PARAMETERS.values():
        if p.per_env and p.field == key:
            return p
    raise ValueError(f"'{key}' is not a per-env twin parameter; use one of {per_env_keys()} "
                     "(palpation.twin.parameters)")


def env_values(key: str, value, n_envs: int) -> np.ndarray:
    """One env key's values for `n_envs` envs (a scalar broadcast), float64; finite, else a ValueError."""
    a = np.asarray(value, np.float64)
    if a.ndim > 1 or a.size not in (1, n_envs):
        raise ValueError(f"env parameter {key}: need a scalar or {n_envs} values, got shape {a.shape}")
    a = np.broadcast_to(a.reshape(-1), (n_envs,))
    if not np.all(np.isfinite(a)):
        raise ValueError(f"env parameter {key}: values must be finite, got {a}")
    return a


def layered_values(params: dict, cfg, n_envs: int) -> dict[str, np.ndarray]:
    """Scope "layered" parameters per env (`params` or the config's); without the layered kernel (cfg.layered)
    only the config's values are allowed."""
    out = {}
    for key in LAYERED_KEYS:
        default = by_env_key(key).default(cfg)
        a = np.asarray(params.get(key, default), np.float64).reshape(-1)
        if a.size not in (1, n_envs) or not np.all(np.isfinite(a)) or np.any(a < 0):
            raise ValueError(f"env parameter {key}: need one finite value >= 0 or {n_envs} "
                             f"of them, got {a}")
        if not cfg.layered and np.any(a != default):
            raise ValueError(f"env parameter {key} differs from the config, which needs the layered "
                             "kernel: set twin.damping.per_env=true or twin.material.shell_thickness > 0")
        out[key] = np.broadcast_to(a, (n_envs,))
    if np.any(out["shell_ratio"] <= 0):
        raise ValueError(f"env parameter shell_ratio must be > 0, got {out['shell_ratio']}")
    return out


def outside_bounds(name: str, low: float, high: float) -> str:
    """Why a search range [low, high] leaves the registry's physical bounds ("" when it does not)."""
    p = PARAMETERS.get(name) or ALIASES.get(name)
    if p is None:
        raise ValueError(f"unknown twin parameter '{name}'; known: {sorted({**PARAMETERS, **ALIASES})}")
    if p.low <= low < high <= p.high:
        return ""
    return (f"range [{low:g}, {high:g}] of '{name}' leaves its physical bounds [{p.low:g}, {p.high:g}] {p.unit} "
            f"({p.why}; palpation/twin/parameters.py)")
