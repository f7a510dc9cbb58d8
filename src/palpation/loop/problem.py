"""A measured set the loop works on (`Problem`), its starting parameters, and its twin simulated at every state.

The loop's data: one `Problem` per measured set (the real photos are one, the self-test has one per injected set),
what the twin has so far (its parameters, effects, rounds) and its simulated markers. `evaluate` simulates many
problems' current twins in one batch; every part of the loop (engine, refit, projected, parsimony, unexplained)
simulates through it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from palpation.calibration.objective import marker_mae_px
from palpation.loop.effects import PARAMS
from palpation.loop.inputs import Target


@dataclass
class Problem:
    name: str
    key: str  # content hash of the measured set (study names)
    targets: list[Target]
    params: dict[str, float]  # every loop parameter's current value
    searched: list[str]  # recalibrated every round
    effects: list[str] = field(default_factory=list)  # added so far
    candidates: list[str] = field(default_factory=list)
    rounds: list[dict] = field(default_factory=list)
    markers: np.ndarray | None = None  # current simulated markers per target
    trust: dict[str, tuple[float, float]] = field(default_factory=dict)  # per-round search bounds
    refit: list = field(default_factory=list)  # refit_dofs at this round's signatures
    done: bool = False
    # the signatures of the last round (candidates, refit, conditional) and the params they were made at:
    # the final check (loop.unexplained) reuses them when the twin did not change since
    last_signatures: dict | None = None
    final: dict | None = None  # loop.unexplained.final_check of the final twin
    reference_attribution: dict | None = None  # real mode: attribution at the starting twin (loop.real)
    starts: list[dict] = field(default_factory=list)  # the last kept try's best distinct trials (final refit)
    noise_px: float | None = None  # detector noise per coordinate (loop.compete: a residual at the noise level)
    parsimony: dict | None = None  # loop.parsimony.prune: the tests of the added effects after the final refit

    def fit_targets(self) -> list[Target]:
        return [t for t in self.targets if t.fit]

    def mae(self, markers: np.ndarray | None = None) -> dict[str, float]:
        m = self.markers if markers is None else markers
        return {t.name: marker_mae_px(x, t.markers) for t, x in zip(self.targets, m)}

    def summary(self, markers: np.ndarray | None = None) -> dict[str, float]:
        mae = self.mae(markers)
        fit = [mae[t.name] for t in self.targets if t.fit]
        held = [mae[t.name] for t in self.targets if not t.fit]
        m = self.markers if markers is None else markers
        energy = sum(float(((x - t.markers) ** 2).sum()) for t, x in zip(self.targets, m) if t.fit)
        return {"fit": float(np.mean(fit)), "heldout": float(np.mean(held)) if held else float("nan"),
                "all": float(np.mean(list(mae.values()))), "fit_energy": energy}


def initial_params(base: Mapping[str, float]) -> dict[str, float]:
    """Every loop parameter at its 'effect off' value, then `base` (E, alpha, ... of the twin)."""
    return {**{k: p.default for k, p in PARAMS.items()}, **dict(base)}


def evaluate(problems: list[Problem], simulate, strict: bool = True) -> dict[str, list[str]]:
    """Simulate each problem's current twin at all its states (one batch).

    A twin that diverges at a state raises; with `strict=False` it is returned instead ({problem: states})
    and that problem's markers are left as they were (a recalibrated try is then refused, not the loop)."""
    jobs = [(t.state, p.params) for p in problems for t in p.targets]
    markers, failed = simulate(jobs)
    i, diverged = 0, {}
    for p in problems:
        n = len(p.targets)
        bad = [t.name for t, f in zip(p.targets, failed[i:i + n]) if f]
        if bad and strict:
            raise ValueError(f"loop '{p.name}': the current twin diverged at {bad}; params {p.params}")
        if bad:
            diverged[p.name] = bad
        else:
            p.markers = markers[i:i + n]
        i += n
    return diverged
