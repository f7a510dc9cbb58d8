"""Per-pixel statistics of thresholded maps and d-bar (SPEC §12).

Prediction = visited AND score >= threshold. Against the truth grown by r in {0, 1, 2} px (r = 0: exact
pixels, the reported numbers) we count TP/FP/FN/TN over every grid pixel, derive MCC (0 for a zero
denominator), F1, precision, recall, accuracy, FG and BG IoU (an empty union counts as 1), and the map
AP over all pixels with unvisited pixels scored -1 (sklearn). Distances: L2 = EDT(~truth_r) at each
predicted pixel; d-bar = their mean at r = 0, in mm (1 px = 1 mm). Several maps (Meat, Sim) sum their
counts and concatenate their distances; a map without any true pixel gives its predictions no distance
(nothing to be near) and they are counted in `n_pred_without_truth`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from sklearn.metrics import average_precision_score

from palpation.mapping.threshold import grow

RADII_PX = (0, 1, 2)
DECILES = tuple(range(10, 100, 10))


def _ratio(num: float, den: float) -> float:
    return float(num / den) if den else 0.0


def _stack(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a)
    return a[None] if a.ndim == 2 else a


def nearest_truth_mm(pred: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, int]:
    """Distances (mm) from each predicted pixel to the nearest true pixel, maps concatenated; and the
    number of predicted pixels in maps that have no true pixel."""
    dists, orphans = [], 0
    for p, t in zip(_stack(pred), _stack(truth)):
        if not p.any():
            continue
        if not t.any():
            orphans += int(p.sum())
            continue
        dists.append(ndimage.distance_transform_edt(~t)[p])
    return (np.concatenate(dists) if dists else np.zeros(0)), orphans


def confusion_counts(pred: np.ndarray, truth: np.ndarray) -> dict:
    pred, truth = np.asarray(pred, bool), np.asarray(truth, bool)
    return {"tp": int((pred & truth).sum()), "fp": int((pred & ~truth).sum()),
            "fn": int((~pred & truth).sum()), "tn": int((~pred & ~truth).sum())}


def scores_from_counts(c: dict) -> dict:
    tp, fp, fn, tn = c["tp"], c["fp"], c["fn"], c["tn"]
    den = math.sqrt(float(tp + fp) * (tp + fn) * (tn + fp) * (tn + fn))
    fg_union, bg_union = tp + fp + fn, tn + fp + fn
    return {"mcc": _ratio(tp * tn - fp * fn, den), "f1": _ratio(2 * tp, 2 * tp + fp + fn),
            "precision": _ratio(tp, tp + fp), "recall": _ratio(tp, tp + fn),
            "accuracy": _ratio(tp + tn, tp + fp + fn + tn),
            "fg_iou": tp / fg_union if fg_union else 1.0, "bg_iou": tn / bg_union if bg_union else 1.0}


def map_ap(score: np.ndarray, truth: np.ndarray) -> float:
    """AP over all pixels of all maps (unvisited pixels carry score -1); NaN with one class only."""
    y = np.asarray(truth, bool).ravel()
    if y.all() or not y.any():
        return float("nan")
    return float(average_precision_score(y, np.asarray(score, np.float64).ravel()))


def map_stats(score: np.ndarray, visited: np.ndarray, truth: np.ndarray, threshold: float,
              radius_px: float = 0) -> dict:
    """Statistics of (M, H, W) or (H, W) maps at one threshold against truth grown by `radius_px`."""
    score, visited, truth = _stack(score), _stack(visited).astype(bool), _stack(truth).astype(bool)
    if not (score.shape == visited.shape == truth.shape):
        raise ValueError(f"map layers differ in shape: score {score.shape}, visited {visited.shape}, "
                         f"truth {truth.shape}")
    truth_r = grow(truth, radius_px)
    pred = visited & (score >= threshold)
    counts = confusion_counts(pred, truth_r)
    d, orphans = nearest_truth_mm(pred, truth_r)
    dist = {"mean": float(d.mean()) if d.size else float("nan"),
            "median": float(np.median(d)) if d.size else float("nan"),
            "deciles": [float(v) for v in np.percentile(d, DECILES)] if d.size else [],
            "n": int(d.size), "n_pred_without_truth": orphans}
    return {"radius_px": radius_px, "threshold": float(threshold), **counts, **scores_from_counts(counts),
            "ap": map_ap(score, truth_r), "distance_mm": dist, "n_px": int(truth.size),
            "n_visited": int(visited.sum()), "n_truth": int(truth_r.sum())}


def all_radii(score, visited, truth, threshold: float, radii=RADII_PX) -> dict:
    """map_stats at each radius; `d_bar_mm` = the mean distance at r = 0."""
    out = {f"r{r}": map_stats(score, visited, truth, threshold, r) for r in radii}
    out["d_bar_mm"] = out["r0"]["distance_mm"]["mean"] if "r0" in out else float("nan")
    return out
