"""The project objective: simulated vs measured markers at the deepest point of each interaction.

Minimised: the mean marker MAE over the measured photos of press, twist_z, twist_x and slide, each
simulated vessel-free to its last waypoint at the depth and angle its file name gives, optionally
holding one interaction out for validation. Every proposal of a batch becomes one environment per
interaction, and the whole batch runs as one twin call.

twist_z (quirk 5): its file name says 90 deg, the reference simulated 30 deg, and the photo shows no
twist; `twist_z_angle="reference"` (default) reproduces the reference, "filename" takes the 90.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from palpation.calibration.params import to_env
from palpation.calibration.search import TrialResult
from palpation.camera import MM_PER_PX
from palpation.measured import MeasuredSet
from palpation.twin.trajectory import CANONICAL_ANGLE_DEG

INTERACTIONS = ("press", "twist_z", "twist_x", "slide")
ANGLE_SOURCES = ("reference", "filename")
GEOMETRIES = ("photo", "canonical")


@dataclass(frozen=True)
class Target:
    """One measured interaction state to reproduce."""

    name: str  # state name in the measured set
    kind: str  # twin trajectory kind
    depth_mm: float | None  # from the file name
    angle_deg: float | None
    markers: np.ndarray  # (127, 2) measured pixels


def marker_mae_px(sim: np.ndarray, real: np.ndarray) -> float:
    """Mean over markers of the Euclidean pixel distance (both in base-graph order)."""
    return float(np.mean(np.linalg.norm(np.asarray(sim, np.float64) - real, axis=-1)))


def photo_targets(mset: MeasuredSet, interactions: Sequence[str] = INTERACTIONS,
                  source: str = "measured set") -> list[Target]:
    """The measured state of each interaction; a missing one is an error naming the set."""
    unknown = [k for k in interactions if k not in INTERACTIONS]
    if unknown or not interactions:
        raise ValueError(f"calibration.interactions: {list(interactions)} must be a non-empty subset "
                         f"of {INTERACTIONS}")
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


def target_geometry(target: Target, geometry: str = "photo", twist_z_angle: str = "reference") -> dict:
    """depth_mm / angle_deg to simulate a target at; absent keys take SPEC's canonical values."""
    if geometry not in GEOMETRIES:
        raise ValueError(f"calibration.geometry must be one of {GEOMETRIES}, got '{geometry}'")
    if twist_z_angle not in ANGLE_SOURCES:
        raise ValueError(f"calibration.twist_z_angle must be one of {ANGLE_SOURCES}, got '{twist_z_angle}'")
    out = {}
    if geometry == "photo" and target.depth_mm is not None:
        out["depth_mm"] = target.depth_mm
    if target.kind in CANONICAL_ANGLE_DEG and geometry == "photo" and target.angle_deg is not None:
        if not (target.kind == "twist_z" and twist_z_angle == "reference"):
            out["angle_deg"] = target.angle_deg
    return out


def undeformed_mae(rest_px: np.ndarray, targets: Sequence[Target]) -> dict[str, float]:
    """Baseline: a sensor that never deforms (markers fixed at `rest_px`) against each photo."""
    return {t.kind: marker_mae_px(rest_px, t.markers) for t in targets}


# simulate(requests) -> (markers (n, 127, 2), failed (n,)); a request is (kind, EnvRequest fields).
Simulator = Callable[[list[tuple[str, dict]]], tuple[np.ndarray, np.ndarray]]


class PhotoObjective:
    """Mean MAE over the fitted interactions (minimised); held-out interactions are only reported."""

    direction = "minimize"

    def __init__(self, targets: Sequence[Target], simulate: Simulator, fit: Sequence[str],
                 fixed: Mapping[str, float] | None = None, worst_px: float = 165.0,
                 geometry: str = "photo", twist_z_angle: str = "reference"):
        unknown = set(fit) - {t.kind for t in targets}
        if unknown or not fit:
            raise ValueError(f"calibration: the fitted interactions must be measured ones, got {list(fit)} "
                             f"(targets: {[t.kind for t in targets]})")
        self.targets, self.simulate, self.fit = list(targets), simulate, list(fit)
        self.fixed = dict(fixed or {})
        self.worst_px = worst_px
        self.geometry = [target_geometry(t, geometry, twist_z_angle) for t in self.targets]
        to_env(self.fixed)  # unknown fixed names fail here, before any simulation

    def requests(self, params: Mapping[str, float]) -> list[tuple[str, dict]]:
        env = {**to_env({**self.fixed, **params}), "vessel": False}
        return [(t.kind, {**env, **geo}) for t, geo in zip(self.targets, self.geometry)]

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
