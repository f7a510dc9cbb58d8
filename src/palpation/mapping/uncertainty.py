"""Per-pixel ensemble of a configuration's seed maps, the "unsure" map variant and its coverage-precision
curve (issue 15). Every seed's map is drawn on the same grid from the same test samples (only the scores
differ), so visited pixels and video truth are shared; a pixel's ensemble score is the mean over seeds of
the per-seed map score (max probability on the pixel, SPEC §12) and its spread their sample std.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from palpation.mapping.lift import UNVISITED, MapStack
from palpation.mapping.threshold import grow
from palpation.metrics.ensemble import COVERAGES, coverage_curve, ensemble, unsure

TP, FP, FN, TN, UNSURE = 0, 1, 2, 3, 4
COLOURS = np.array([[0, 170, 0], [40, 90, 255], [230, 30, 30], [0, 0, 0], [255, 200, 0]], np.uint8)
UNVISITED_RGB = np.array([128, 128, 128], np.uint8)


@dataclass
class EnsembleMap:
    mean: np.ndarray  # (M, H, W), UNVISITED where no sample landed
    spread: np.ndarray  # (M, H, W), 0 where unvisited
    visited: np.ndarray
    truth: np.ndarray
    n_seeds: int
    threshold: float

    @property
    def unsure(self) -> np.ndarray:
        return self.visited & unsure(self.mean, self.spread, self.threshold)

    def classes(self) -> np.ndarray:
        """Per visited pixel TP/FP/FN/TN of the mean at the threshold, or UNSURE; -1 unvisited."""
        pred = self.mean >= self.threshold
        out = np.select([pred & self.truth, pred & ~self.truth, ~pred & self.truth], [TP, FP, FN], TN)
        out = np.where(self.unsure, UNSURE, out)
        return np.where(self.visited, out, -1).astype(np.int8)

    def rgb(self) -> np.ndarray:
        """(M, H, W, 3) colours of `classes`: TP green, FP blue, FN red, TN black, unsure amber."""
        c = self.classes()
        return np.where((c >= 0)[..., None], COLOURS[np.clip(c, 0, None)], UNVISITED_RGB)

    def coverage_curve(self, tolerance_px: float = 3.0, coverages=COVERAGES) -> list[dict]:
        """Precision of the committed positive pixels (a hit lies within the tolerance of a truth pixel)
        and recall of the truth pixels (found within the tolerance of a committed positive pixel)."""
        v = self.visited
        m = self.mean[v]
        shape = self.mean.shape

        def near(mask_v: np.ndarray) -> np.ndarray:  # grow on the grid, read back at visited pixels
            full = np.zeros(shape, bool)
            full[v] = mask_v
            return grow(full, tolerance_px)[v]

        return coverage_curve(m, self.spread[v], self.truth[v], self.threshold, coverages, near, near)


def ensemble_map(stacks: list[MapStack], threshold: float = 0.5) -> EnsembleMap:
    """Seed maps of one configuration (same grid, samples and truth) -> the ensemble map."""
    if not stacks:
        raise ValueError("an ensemble map needs at least one seed's map stack")
    first = stacks[0]
    for s in stacks[1:]:
        if s.score.shape != first.score.shape or not np.array_equal(s.visited, first.visited):
            raise ValueError("seed maps differ in grid or visited pixels; they must come from the same test samples")
    mean, spread = ensemble([s.score for s in stacks])
    mean = np.where(first.visited, mean, UNVISITED).astype(np.float32)
    spread = np.where(first.visited, spread, 0.0).astype(np.float32)
    return EnsembleMap(mean, spread, first.visited, first.truth, len(stacks), threshold)
