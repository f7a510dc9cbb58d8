"""The registry of twin parameters a calibration may search or hold fixed, with their units.

A registry name maps to one per-env parameter of `BatchedTwin` (runner.PARAM_DEFAULTS) through a
scale, so bounds can be written in the units a source quotes: `k_n_ref` is SPEC's reference-unit
contact stiffness (x5 length scale), which the twin takes as k_n = k_n_ref / 5 (twin.config). The
residual loop adds names with `register`; a name the simulator does not accept is refused here,
before any simulation.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Iterable, Mapping, Sequence

from palpation.calibration.search import ParamSpec, validate_space
from palpation.twin.config import REF_LENGTH_SCALE, TwinConfig
from palpation.twin.runner import PARAM_DEFAULTS

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TwinParam:
    name: str  # registry name, as written in conf/calibration/*.yaml
    env_key: str  # per-env parameter of BatchedTwin
    unit: str
    scale: float = 1.0  # twin value = registry value * scale
    acts_via: str = "material"  # material | vessel | phantom | contact: where it has any effect


REGISTRY: dict[str, TwinParam] = {}


def register(param: TwinParam) -> TwinParam:
    """Add (or replace) a searchable name; its env_key must be one the simulator takes per env."""
    if param.env_key not in PARAM_DEFAULTS:
        raise ValueError(f"twin parameter '{param.name}': env_key '{param.env_key}' is not a per-env "
                         f"parameter of the twin; use one of {sorted(PARAM_DEFAULTS)}")
    if not param.scale > 0:
        raise ValueError(f"twin parameter '{param.name}': scale must be > 0, got {param.scale}")
    REGISTRY[param.name] = param
    return param


for _p in (
    TwinParam("E", "E", "Pa"),
    TwinParam("nu", "nu", "1"),
    TwinParam("k_n", "k_n", "N/m (physical)", acts_via="vessel"),
    TwinParam("k_n_ref", "k_n", "reference units (x5 length); twin k_n = k_n_ref / 5",
              1.0 / REF_LENGTH_SCALE, acts_via="vessel"),
    TwinParam("c_n", "c_n", "N s/m^2 (x depth, quirk 11)", acts_via="vessel"),
    TwinParam("k_t", "k_t", "N s/m", acts_via="contact"),
    TwinParam("k_t_ref", "k_t", "reference units; twin k_t = k_t_ref / 5", 1.0 / REF_LENGTH_SCALE,
              acts_via="contact"),
    TwinParam("mu", "mu", "1", acts_via="contact"),
    TwinParam("k_s", "k_s", "N/m per node", acts_via="phantom"),
    TwinParam("c_s", "c_s", "N s/m^2", acts_via="phantom"),
):
    register(_p)


def check_names(names: Iterable[str], where: str) -> None:
    unknown = [n for n in names if n not in REGISTRY]
    if unknown:
        raise ValueError(f"{where}: unknown twin parameter(s) {unknown}; known: {sorted(REGISTRY)} "
                         "(add one with palpation.calibration.params.register)")


def check_space(space: Sequence[ParamSpec], fixed: Mapping[str, float]) -> None:
    """Names, bounds and fixed values, all checked before anything is simulated."""
    validate_space(space, known=set(REGISTRY))
    check_names(fixed, "calibration.fixed")
    keys = [REGISTRY[n].env_key for n in [*(p.name for p in space), *fixed]]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise ValueError(f"calibration: twin parameter(s) {dup} are set twice (searched and fixed, or "
                         "under two names such as k_n and k_n_ref); keep one")
    for name, value in fixed.items():
        if not isinstance(value, (int, float)) or value != value:
            raise ValueError(f"calibration.fixed.{name}: need a number, got {value!r}")


def inert(names: Iterable[str], vessel: bool, phantom_contact: bool) -> list[str]:
    """Names that cannot change the objective: contact terms with nothing to touch (quirk 1)."""
    touches = {"material": True, "vessel": vessel, "phantom": phantom_contact,
               "contact": vessel or phantom_contact}
    return [n for n in names if not touches[REGISTRY[n].acts_via]]


def warn_inert(space: Sequence[ParamSpec], vessel: bool, cfg: TwinConfig, where: str) -> list[str]:
    dead = inert([p.name for p in space], vessel, cfg.contact.phantom_contact)
    if dead:
        log.warning("%s: %s cannot act on this objective (no contact partner: vessel=%s, "
                    "phantom_contact=%s); the search will not identify them", where, dead, vessel,
                    cfg.contact.phantom_contact)
    return dead


def to_env(params: Mapping[str, float]) -> dict[str, float]:
    """Registry values -> per-env twin parameters (EnvRequest fields, twin units)."""
    check_names(params, "twin parameters")
    return {REGISTRY[n].env_key: float(v) * REGISTRY[n].scale for n, v in params.items()}


def twin_overrides(params: Mapping[str, float]) -> dict[str, dict[str, float]]:
    """Registry values -> the TwinConfig sections and fields they set, e.g. {"material": {"E": ...}}."""
    out: dict[str, dict[str, float]] = {}
    for key, value in to_env(params).items():
        section, field = PARAM_DEFAULTS[key]
        out.setdefault(section, {})[field] = value
    return out
