"""The map operating point (SPEC §12 [fixed]): the most sensitive threshold that keeps precision >= 0.9
when a prediction within 3 mm of the truth counts as right.

All maps of a run are pooled. The truth is grown by an L2 disc of radius 3 px (EDT <= 3); candidates
are the distinct visited scores in descending order; at the k-th predicted pixel precision = cumTP / k
and recall = cumTP / |grown truth| (unvisited truth included). Among candidates with precision >= 0.9
and >= 20 predicted pixels take the max recall (ties: max precision, then the higher threshold);
otherwise the F1-optimal candidate, flagged "f1_fallback". The tolerance serves only this choice:
the reported statistics use exact pixels (palpation.mapping.stats).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import ndimage

RULE_PRECISION = "precision>=0.9@3mm"
RULE_FALLBACK = "f1_fallback"


def grow(truth: np.ndarray, radius_px: float) -> np.ndarray:
    """Truth grown by an L2 disc per map: EDT(~truth) <= radius; (H, W) or (M, H, W)."""
    truth = np.asarray(truth, bool)
    if radius_px <= 0:
        return truth.copy()
    stack = truth[None] if truth.ndim == 2 else truth
    out = np.zeros_like(stack)
    for i, t in enumerate(stack):
        if t.any():  # EDT of an all-true input is not a distance to anything
            out[i] = ndimage.distance_transform_edt(~t) <= radius_px
    return out[0] if truth.ndim == 2 else out


@dataclass(frozen=True)
class OperatingPoint:
    threshold: float
    rule: str
    precision: float  # at the tolerance
    recall: float
    f1: float
    n_pred: int
    tolerance_mm: float
    min_precision: float
    min_pixels: int

    def to_dict(self) -> dict:
        return asdict(self)


def tolerance_curve(score: np.ndarray, visited: np.ndarray, truth: np.ndarray, tolerance_mm: float = 3.0) -> dict:
    """Precision, recall, F1 and predicted-pixel count at every distinct visited score (descending)."""
    score, visited = np.asarray(score), np.asarray(visited, bool)
    grown = grow(truth, tolerance_mm)
    s, hit = score[visited].astype(np.float64), grown[visited]
    if s.size == 0:
        raise ValueError("threshold selection: no visited pixel in any map; nothing was predicted (empty "
                         "prediction set or every sample off the grid)")
    order = np.argsort(-s, kind="stable")
    s, hit = s[order], hit[order]
    cum_tp = np.cumsum(hit)
    last = np.r_[np.flatnonzero(np.diff(s) != 0), s.size - 1]  # last index of each distinct score
    k = last + 1
    tp = cum_tp[last]
    n_true = int(grown.sum())
    precision = tp / k
    recall = tp / n_true if n_true else np.zeros(len(k))
    den = precision + recall
    f1 = np.divide(2 * precision * recall, den, out=np.zeros_like(den), where=den > 0)
    return {"threshold": s[last], "precision": precision, "recall": recall, "f1": f1, "n_pred": k,
            "n_true_grown": n_true}


def choose_threshold(score: np.ndarray, visited: np.ndarray, truth: np.ndarray, tolerance_mm: float = 3.0,
                     min_precision: float = 0.9, min_pixels: int = 20) -> tuple[OperatingPoint, dict]:
    """The operating point of pooled maps (M, H, W) and the curve it was chosen on."""
    c = tolerance_curve(score, visited, truth, tolerance_mm)
    ok = (c["precision"] >= min_precision) & (c["n_pred"] >= min_pixels)
    if ok.any():
        idx = np.flatnonzero(ok)
        # lexsort: last key is primary -> max recall, then max precision, then the higher threshold
        i = idx[np.lexsort((c["threshold"][idx], c["precision"][idx], c["recall"][idx]))[-1]]
        rule = RULE_PRECISION
    else:
        i = int(np.lexsort((c["threshold"], c["f1"]))[-1])
        rule = RULE_FALLBACK
    op = OperatingPoint(float(c["threshold"][i]), rule, float(c["precision"][i]), float(c["recall"][i]),
                        float(c["f1"][i]), int(c["n_pred"][i]), float(tolerance_mm), float(min_precision),
                        int(min_pixels))
    return op, c
