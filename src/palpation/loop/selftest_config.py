"""Settings of the fixed self-test (`loop.selftest`, Hydra node of LoopConfig) and its case strings.

A case is '+'-joined effects of the candidate list (loop.effects) or outside it (`unlisted:<name>`, loop.unlisted);
`parse_case` reads and checks one. The self-test itself runs in loop.selftest.fixed.
"""

from __future__ import annotations

from dataclasses import dataclass

from palpation.config_ranges import SEED, Choice, DictOf, Int, ListOf, Num, Text, ranged
from palpation.loop.effects import EFFECTS
from palpation.loop.unlisted import UNLISTED, UNLISTED_PREFIX


@dataclass
class SelftestConfig:
    """Measured-like sets made by the twin with hidden effects on, then the loop on each (loop.selftest.fixed).

    Size = len(cases) x runs_per_case. A case is '+'-joined effects; `unlisted:<name>` is one outside the
    candidate list (loop.unlisted.UNLISTED)."""

    cases: list[str] = ranged(rule=ListOf(Text()), factory=lambda: [
        "surface_contact", "camera", "viscous", "layered", "marker_anchor",  # singles
        "surface_contact+friction",  # a dependent pair (friction acts only through contact)
        "surface_contact+mount", "surface_contact+camera", "camera+layered", "viscous+marker_anchor",  # pairs
        "unlisted:image_distortion", "unlisted:marker_defect"])  # outside the list
    runs_per_case: int = ranged(1, Int(ge=1))
    strength_low: float = ranged(1.0, Num(gt=0))  # injected strength in nominal steps, drawn uniformly in [low, high]
    strength_high: float = ranged(2.5, Num(gt=0))
    noise_px: float = ranged(0.2, Num(ge=0))  # std per coordinate (SPEC §13.2: photo noise < 0.2 px)
    # on in the starting twin (none: as the real mode)
    base_effects: list[str] = ranged(rule=ListOf(Choice(*EFFECTS), 0, unique=True), factory=list)
    base_params: dict[str, float] = ranged(rule=DictOf(Num()), factory=lambda: {"E": 1.2225e6})
    states: list[str] = ranged(rule=ListOf(Text(), unique=True), factory=lambda: ["press", "twist_z", "twist_x"])
    holdout: list[str] = ranged(rule=ListOf(Text(), 0, unique=True), factory=lambda: ["twist_z"])
    max_rounds: int = ranged(1, Int(ge=1))
    seed: int = ranged(0, SEED)


def parse_case(case: str, base_effects, where: str = "loop.selftest.cases") -> tuple[list[str], list[str]]:
    """'surface_contact+friction' -> (['surface_contact', 'friction'], []); 'unlisted:x' -> ([], ['x'])."""
    parts = [c.strip() for c in str(case).split("+") if c.strip()]
    inl = [c for c in parts if not c.startswith(UNLISTED_PREFIX)]
    unl = [c[len(UNLISTED_PREFIX):] for c in parts if c.startswith(UNLISTED_PREFIX)]
    bad = [c for c in inl if c not in EFFECTS] + [UNLISTED_PREFIX + u for u in unl if u not in UNLISTED]
    if bad or not parts:
        raise ValueError(f"{where}: case '{case}' names unknown effect(s) {bad}; known: {sorted(EFFECTS)} and "
                         f"{[UNLISTED_PREFIX + u for u in UNLISTED]}, joined with '+'")
    for e in inl:
        missing = [r for r in EFFECTS[e].requires if r not in inl and r not in base_effects]
        if missing:
            raise ValueError(f"{where}: case '{case}': {e} acts only through {missing}; inject them together "
                             f"('{'+'.join([*missing, e])}') or add them to loop.selftest.base_effects")
    return inl, unl
