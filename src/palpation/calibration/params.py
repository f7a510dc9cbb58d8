"""The twin parameters a calibration may search or hold fixed: the per-env entries of twin.parameters.

A name is a registry entry of scope "env" (E, nu, k_n, c_n, k_s, c_s, k_t, mu) or one of its aliases in
the units a source quotes: `k_n_ref` is SPEC's reference-unit contact stiffness (x5 length scale), which
the twin takes as k_n = k_n_ref / 5. A search range left out (conf/calibration/*.yaml: `{name: E}`)
takes the registry's physical bounds; one that leaves them is logged. Every name is checked here,
before any simulation. New names are added to the twin's registry, not here.
"""

from __future__ import annotations

import logging
from typing import Iterable, Mapping, Sequence

from palpation.calibration.search import ParamSpec, validate_space
from palpation.twin.config import TwinConfig
from palpation.twin.parameters import ALIASES, PARAMETERS, TwinParameter, by_env_key, outside_bounds

log = logging.getLogger(__name__)

# name -> registry entry (its `field` is the BatchedTwin env key; twin value = value * scale)
REGISTRY: dict[str, TwinParameter] = {**{n: p for n, p in PARAMETERS.items() if p.scope == "env"}, **ALIASES}


def check_names(names: Iterable[str], where: str) -> None:
    unknown = [n for n in names if n not in REGISTRY]
    if unknown:
        raise ValueError(f"{where}: unknown twin parameter(s) {unknown}; known: {sorted(REGISTRY)} "
                         "(add one to palpation/twin/parameters.py)")


def check_space(space: Sequence[ParamSpec], fixed: Mapping[str, float]) -> None:
    """Names, bounds and fixed values, all checked before anything is simulated."""
    validate_space(space, known=set(REGISTRY))
    for p in space:  # allowed (a study may probe past them) but said: the twin was not meant to go there
        why = outside_bounds(p.name, p.low, p.high)
        if why:
            log.warning("calibration.params.%s: %s", p.name, why)
    check_names(fixed, "calibration.fixed")
    keys = [REGISTRY[n].field for n in [*(p.name for p in space), *fixed]]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise ValueError(f"calibration: twin parameter(s) {dup} are set twice (searched and fixed, or "
                         "under two names such as k_n and k_n_ref); keep one")
    for name, value in fixed.items():
        if not isinstance(value, (int, float)) or value != value:
            raise ValueError(f"calibration.fixed.{name}: need a number, got {value!r}")


def inert(names: Iterable[str], vessel: bool, phantom_contact: bool) -> list[str]:
    """Names that cannot change the objective: contact terms with nothing to touch (quirk 1)."""
    touches = {"": True, "vessel": vessel, "phantom": phantom_contact, "contact": vessel or phantom_contact}
    return [n for n in names if not touches[REGISTRY[n].needs]]


def warn_inert(space: Sequence[ParamSpec], vessel: bool, cfg: TwinConfig, where: str) -> list[str]:
    dead = inert([p.name for p in space], vessel, cfg.contact.phantom_contact)
    if dead:
        log.warning("%s: %s cannot act on this objective (no contact partner: vessel=%s, "
                    "phantom_contact=%s); the search will not identify them", where, dead, vessel,
                    cfg.contact.phantom_contact)
    return dead


def to_env(params: Mapping[str, float]) -> dict[str, float]:
    """Registry values -> per-env twin parameters (EnvRequest keywords, twin units)."""
    check_names(params, "twin parameters")
    return {REGISTRY[n].field: float(v) * REGISTRY[n].scale for n, v in params.items()}


def twin_overrides(params: Mapping[str, float]) -> dict[str, dict[str, float]]:
    """Registry values -> the TwinConfig sections and fields they set, e.g. {"material": {"E": ...}}."""
    out: dict[str, dict[str, float]] = {}
    for key, value in to_env(params).items():
        out.setdefault(by_env_key(key).section, {})[key] = value
    return out
