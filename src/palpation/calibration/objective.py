"""Calibration objectives: simulated vs measured markers at the deepest point of each interaction.

The project objective (default) is the mean marker MAE over the measured photos of press, twist_z,
twist_x and slide, each simulated at the depth and angle its file name gives, optionally holding one
interaction out for validation. Every proposal of a batch becomes one environment per interaction,
and the whole batch runs as one twin run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from palpation.calibration.search import TrialResult
from palpation.camera import MM_PER_PX
from palpation.measured import MeasuredSet

INTERACTIONS = ("press", "twist_z", "twist_x", "slide")
# Twin parameters a search may vary per environment (names as in BatchedTwin's env parameters).
SEARCHABLE = ("E", "nu", "k_n", "c_n", "k_t", "mu", "k_s", "c_s")


@dataclass(frozen=True)
class Target:
    """One measured interaction state to reproduce."""

    name: str  # state name in the measured set
    kind: str  # twin trajectory kind
    depth_mm: float | None
    angle_deg: float | None
    markers: np.ndarray  # (127, 2) measured pixels


def marker_mae_px(sim: np.ndarray, real: np.ndarray) -> float:
    """Mean over markers of the Euclidean pixel distance (both in base-graph order)."""
    return float(np.mean(np.linalg.norm(np.asarray(sim, np.float64) - real, axis=-1)))


def photo_targets(mset: MeasuredSet, interactions: Sequence[str] = INTERACTIONS,
                  source: str = "measured set") -> list[Target]:
    """The measured state of each interaction; a missing one is an error naming the set."""
    by_kind: dict[str, list] = {}
    for i, state in enumerate(mset.states):
        by_kind.setdefault(state.trajectory, []).append((i, state))
    missing = [k for k in interactions if k not in by_kind]
    if missing:
        raise ValueError(f"{source}: no measured state for interaction(s) {missing}; it has "
                         f"{sorted(by_kind)}. Add the photos or drop them from calibration.interactions")
    targets = []
    for kind in interactions:
        i, state = by_kind[kind][0]
        targets.append(Target(state.name, kind, state.depth_mm, state.angle_deg, mset.markers[i]))
    return targets


def undeformed_mae(mset: MeasuredSet, targets: Sequence[Target]) -> dict[str, float]:
    """Baseline: a sensor that never deforms (the rest markers) against each photo."""
    return {t.kind: marker_mae_px(mset.rest, t.markers) for t in targets}


# simulate(requests) -> (markers (n, 127, 2), failed (n,)); a request is (kind, env params).
Simulator = Callable[[list[tuple[str, dict]]], tuple[np.ndarray, np.ndarray]]


class PhotoObjective:
    """Mean MAE over the fitted interactions (minimised); held-out interactions are only reported."""

    def __init__(self, targets: Sequence[Target], simulate: Simulator, fit: Sequence[str],
                 fixed: dict[str, float] | None = None, worst_px: float = 165.0,
                 use_photo_geometry: bool = True):
        unknown = set(fit) - {t.kind for t in targets}
        if unknown or not fit:
            raise ValueError(f"calibration.fit must name measured interactions, got {list(fit)}")
        self.targets, self.simulate, self.fit = list(targets), simulate, list(fit)
        self.fixed = dict(fixed or {})
        self.worst_px = worst_px
        self.use_photo_geometry = use_photo_geometry

    def requests(self, params: dict[str, float]) -> list[tuple[str, dict]]:
        out = []
        for t in self.targets:
            env = {**self.fixed, **params}
            if self.use_photo_geometry:
                env.update({k: v for k, v in (("depth_mm", t.depth_mm), ("angle_deg", t.angle_deg))
                            if v is not None})
            out.append((t.kind, env))
        return out

    def per_photo_mae(self, markers: np.ndarray) -> dict[str, float]:
        return {t.kind: marker_mae_px(m, t.markers) for t, m in zip(self.targets, markers)}

    def evaluate(self, proposals: list[dict[str, float]]) -> list[TrialResult]:
        requests = [r for p in proposals for r in self.requests(p)]
        markers, failed = self.simulate(requests)
        k = len(self.targets)
        results = []
        for j in range(len(proposals)):
            block, bad = markers[j * k:(j + 1) * k], failed[j * k:(j + 1) * k]
            if bad.any() or not np.all(np.isfinite(block)):
                results.append(TrialResult(self.worst_px, True, {}))
                continue
            mae = self.per_photo_mae(block)
            fit = float(np.mean([mae[i] for i in self.fit]))
            held = [mae[t.kind] for t in self.targets if t.kind not in self.fit]
            metrics = {f"mae_px/{name}": v for name, v in mae.items()}
            metrics.update({"mae_px/fit": fit, "mae_mm/fit": fit * MM_PER_PX})
            if held:
                metrics["mae_px/heldout"] = float(np.mean(held))
            results.append(TrialResult(min(fit, self.worst_px), False, metrics))
        return results
