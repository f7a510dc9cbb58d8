"""Settings of the generative self-test (loop.generative; the draw and the runs: loop.selftest.generative).

Strength ranges are [detectable, stable] in nominal steps (loop.effects), drawn log-uniformly. They are declared,
not derived per run (a derivation through the twin would make a run's truth depend on the device's floats); the
reasons, from the fixed self-test's measured runs (docs/results/loop_selftest.csv, seed 0, coarse mesh, 0.2 px
noise, no contact), are beside each default. A draw outside its own stable range diverges and is drawn again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from palpation.config_ranges import SEED, Choice, DictOf, Int, ListOf, Num, ranged
from palpation.loop.effects import EFFECTS, PARAMS, bounds, move
from palpation.loop.unlisted import UNLISTED

SPLITS = ("dev", "test")
TEST_SEED_START = 1000  # dev seeds lie below, test seeds at or above: the two truths never share a stream
MAX_EFFECTS = 3
PAIR = ListOf(Num(gt=0), 2, 2)  # [low, high], checked low <= high in validate()


def _strengths() -> dict[str, list[float]]:
    # surface_contact is drawn as the contact stiffness (k_s below), the others here
    return {"friction": [1.0, 2.5],  # (k_t, mu) + (20, 0.5) a step: 2.5 = mu 1.25 of its 1.5 bound
            "camera": [1.0, 2.5],  # 1.24 steps: MAE 0.32 px over the 0.25 px noise floor (run 5); bounds at 3
            "mount": [1.0, 2.5],  # with contact, 1.2 steps named (run 30); bounds at 3 steps (1.5 mm, 6 deg)
            "viscous": [1.2, 2.2],  # 1.09 steps is below the gate's power (run 10); alpha ~1 N s/m (2.4) diverges
            "layered": [1.2, 2.0],  # 1.27 named (run 15); 1 + 2 = ratio 3: E x ratio <= 4.2 MPa, coarse-stable
            "marker_anchor": [0.2, 2.5]}  # 1 step moves 3.4 px (run 20); 2.5 = anchor 1.25 of its 1.5 bound


@dataclass
class GenerativeConfig:
    """Each run draws its truth from np.random.default_rng([seed, run]): 0-3 in-list effects (requires
    honoured), log-uniform strengths, E and the contact stiffness, and with probability `unlisted_share` one
    effect of the outside library (loop.unlisted). Dev seeds choose mechanisms and thresholds; test seeds are
    run once, at the end, with the same settings."""

    split: str = ranged("dev", Choice(*SPLITS))
    dev_seeds: list[int] = ranged(rule=ListOf(Int(ge=0, lt=TEST_SEED_START), unique=True), factory=lambda: [0])
    test_seeds: list[int] = ranged(rule=ListOf(Int(ge=TEST_SEED_START, le=SEED.le), unique=True),
                                   factory=lambda: [TEST_SEED_START])
    runs: int = ranged(12, Int(ge=1))  # per seed; run r of seed s is remade alone from (s, r)
    batch: int = ranged(0, Int(ge=0))  # runs advancing in lockstep, saved after each batch (0 = all at once)
    max_rounds: int = ranged(3, Int(ge=1))  # up to 3 in-list effects, one a round (pairs may come together)
    n_effects: list[float] = ranged(rule=ListOf(Num(ge=0, le=1), 1, MAX_EFFECTS + 1),  # P(0), P(1), ... in-list
                                    factory=lambda: [0.1, 0.3, 0.3, 0.3])
    unlisted_share: float = ranged(0.25, Num(ge=0, le=1))  # runs with one outside effect
    strengths: dict[str, list[float]] = ranged(rule=DictOf(PAIR), factory=_strengths)
    # the base twin's E and, where contact is on (injected or in selftest.base_effects), k_s: log-uniform. The loop
    # starts from selftest.base_params (E 1.2225 MPa, no contact), as on the photos. E within both presets' search
    # bounds (paper: 1.4 MPa, reference-mesh stability); k_s: 0.3-3 nominal steps (2000 N/m: a 16-20 px press)
    E: list[float] = ranged(rule=PAIR, factory=lambda: [7.0e5, 1.4e6])
    k_s: list[float] = ranged(rule=PAIR, factory=lambda: [600.0, 6000.0])
    unlisted: dict[str, list[float]] = ranged(  # the outside kinds drawn from, each with its strength range
        rule=DictOf(PAIR, 1), factory=lambda: {n: list(u.strength) for n, u in UNLISTED.items()})
    noise_px: float = ranged(0.2, Num(ge=0))  # detector noise per coordinate, as the fixed self-test

    def seeds(self) -> list[int]:
        return list(self.dev_seeds if self.split == "dev" else self.test_seeds)

    def validate(self, loop) -> "GenerativeConfig":
        """Checks that need the loop's settings (a drawn truth must lie inside the search bounds)."""
        where = "loop.generative"
        bad = [s for s in self.dev_seeds if not 0 <= s < TEST_SEED_START] + \
            [s for s in self.test_seeds if s < TEST_SEED_START]
        if bad or self.split not in SPLITS:
            raise ValueError(f"{where}: split={self.split} (dev|test), dev seeds in [0, {TEST_SEED_START}) and test "
                             f"seeds >= {TEST_SEED_START} (disjoint truths); got {bad}")
        p = np.asarray(self.n_effects, float)
        if not 1 <= len(p) <= MAX_EFFECTS + 1 or (p < 0).any() or abs(p.sum() - 1) > 1e-6:
            raise ValueError(f"{where}.n_effects={list(self.n_effects)}: need probabilities of 0..k in-list effects "
                             f"(k <= {MAX_EFFECTS}) that sum to 1")
        unknown = [e for e in self.strengths if e not in EFFECTS or e == "surface_contact"] + \
            [e for e in loop.effects if e != "surface_contact" and e not in self.strengths] + \
            [u for u in self.unlisted if u not in UNLISTED]
        if unknown:
            raise ValueError(f"{where}: strengths need every candidate of loop.effects but surface_contact (drawn as "
                             f"k_s), unlisted only kinds of {sorted(UNLISTED)}; wrong or missing: {unknown}")
        pairs = {"E": self.E, "k_s": self.k_s, **{f"strengths.{k}": v for k, v in self.strengths.items()},
                 **{f"unlisted.{k}": v for k, v in self.unlisted.items()}}
        for key, (lo, hi) in pairs.items():
            if not 0 < lo <= hi:
                raise ValueError(f"{where}.{key}=[{lo}, {hi}]: need 0 < low <= high")
        for name in ("E", "k_s"):
            lo, hi = bounds(name, loop.search.bounds)
            if not lo <= pairs[name][0] <= pairs[name][1] <= hi:
                raise ValueError(f"{where}.{name}={pairs[name]} leaves the search bounds [{lo:g}, {hi:g}] "
                                 "(loop.search.bounds): the loop could not reach the truth")
        for e, (_, hi) in self.strengths.items():  # every dof at the top strength, either sign where allowed
            for d in EFFECTS[e].dofs:
                for sign in ((1,) if d.nonneg or len(EFFECTS[e].dofs) == 1 else (1, -1)):
                    moved = move({n: PARAMS[n].default for n, _, _ in d.moves}, d, sign * hi, loop.method.steps)
                    out = [n for n, v in moved.items() if not bounds(n, loop.search.bounds)[0] <= v
                           <= bounds(n, loop.search.bounds)[1]]
                    if out:
                        raise ValueError(f"{where}.strengths.{e}: {hi} steps moves {out} out of the search bounds "
                                         "(loop.search.bounds): lower the top strength")
        return self
