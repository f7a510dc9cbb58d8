"""The loop's starting twin: which effects a TwinConfig already has on, and at what values.

The loop varies its parameters per env (loop.simulate), so whatever a user sets in the twin config
(`twin.contact.phantom_contact=true twin.contact.k_s=2000`, a camera shift, a fitted.yaml of an earlier
loop) must become the starting values of those parameters, and the effects it switches on leave the
candidate list. A value the loop cannot honour (a friction coefficient without any contact to act
on, a shell thickness other than the loop's) is refused with one line, never dropped.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from palpation.loop.effects import EFFECTS, PARAMS
from palpation.readers import read_yaml
from palpation.twin.config import CameraConfig, MarkerConfig, MountConfig, TwinConfig
from palpation.twin.parameters import PARAMETERS

REFERENCE = TwinConfig()


def acts(cfg: TwinConfig, needs: str) -> bool:
    """Whether the switch a parameter `needs` (twin.parameters docstring) is on in `cfg` (no vessel here)."""
    if needs in ("phantom", "contact"):
        return bool(cfg.contact.phantom_contact)
    if needs == "shell":
        return cfg.material.shell_thickness > 0
    return needs != "vessel"


def start_twin(cfg: TwinConfig, shell_thickness_m: float) -> tuple[list[str], dict[str, float]]:
    """(effects already on, every loop parameter's starting value) of the twin `cfg`.

    A parameter whose switch is off starts at its off value; an effect is on when one of its switch-like
    parameters (not a multiplicative base such as alpha, LoopStep mode 'mul') differs from its off value.
    """
    if cfg.material.shell_thickness > 0 and abs(cfg.material.shell_thickness - shell_thickness_m) > 1e-12:
        raise ValueError(f"twin.material.shell_thickness={cfg.material.shell_thickness} differs from the loop's "
                         f"shell ({shell_thickness_m} m); set loop.shell_thickness_mm="
                         f"{cfg.material.shell_thickness * 1e3:g} or drop the twin override")
    params = {}
    for name, p in PARAMS.items():
        entry = PARAMETERS[name]
        value = float(entry.default(cfg))
        if acts(cfg, entry.needs):
            params[name] = value
            continue
        if value != float(entry.default(REFERENCE)):
            raise ValueError(f"twin.{entry.section}.{entry.field}={entry.default(cfg) * entry.scale:g} acts only "
                             f"with {entry.needs} on ({_switch(entry.needs)}); switch it on or drop the override")
        params[name] = p.default
    on = [e for e, eff in EFFECTS.items()
          if any(PARAMETERS[n].loop.mode != "mul" and params[n] != PARAMS[n].default for n in eff.params)]
    return on, params


def _switch(needs: str) -> str:
    return {"phantom": "twin.contact.phantom_contact=true", "contact": "twin.contact.phantom_contact=true",
            "shell": "loop shell: twin.material.shell_thickness > 0"}.get(needs, needs)


def nominal_projection(cfg: TwinConfig) -> TwinConfig:
    """`cfg` with camera, mount and marker model nominal: the loop carries them per env (start_twin)."""
    return replace(cfg, camera=CameraConfig(), mount=MountConfig(), markers=MarkerConfig())


def read_start(path: str | Path) -> dict:
    """The twin overrides of a starting-twin file (a twin_fit/fitted.yaml, package twin) as a nested dict."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"loop start={path}: no such file; pass a twin option such as "
                         "results/loop/twin_fit/fitted.yaml or use twin.* overrides")
    return read_yaml(p, "pass a twin option written by the loop or the calibration, a mapping of twin sections "
                     "(e.g. contact: {k_s: 2000})", "loop start file")
