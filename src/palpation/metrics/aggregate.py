"""Across-seed summaries, best-of-five selection and mean PR curves (SPEC §11)."""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
from sklearn.metrics import precision_recall_curve

GRID = np.linspace(0.0, 1.0, 201)


def summarise_seeds(values: Sequence[float]) -> dict:
    """mean, sample std (ddof 1; NaN for one seed), min, max, n."""
    v = np.asarray(values, np.float64)
    if v.size == 0:
        raise ValueError("summarise_seeds needs at least one value")
    return {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else float("nan"),
            "min": float(v.min()), "max": float(v.max()), "n": int(v.size)}


def best_of_five(runs: Sequence[Mapping]) -> Mapping:
    """The run with the highest AP on its own test set; AUROC breaks ties (then the lower seed)."""
    if not runs:
        raise ValueError("best_of_five needs at least one run")
    return max(runs, key=lambda r: (r["ap"], r["auroc"], -r.get("seed", 0)))


def pr_curve(probs, labels) -> dict:
    """Precision, recall and threshold per operating point; the last point (recall 0) gets threshold 1."""
    precision, recall, thresholds = precision_recall_curve(np.asarray(labels).astype(bool), probs)
    return {"precision": precision, "recall": recall, "threshold": np.append(thresholds, 1.0)}


def resample(x: np.ndarray, ys: Sequence[np.ndarray], grid: np.ndarray = GRID) -> list[np.ndarray]:
    """Sort by x, keep the max y per duplicate x, interpolate each y onto `grid`.

    The first y decides which point survives a duplicate x; the others follow that point.
    """
    x = np.asarray(x, np.float64)
    order = np.lexsort((-np.asarray(ys[0], np.float64), x))  # x ascending, y descending
    x_sorted = x[order]
    keep = np.r_[True, np.diff(x_sorted) > 0]  # first of each x run = its max y
    return [np.interp(grid, x_sorted[keep], np.asarray(y, np.float64)[order][keep]) for y in ys]


def mean_curve(curves: Sequence[Mapping], x: str = "recall", y: str = "precision",
               extra: Sequence[str] = ("threshold",), grid: np.ndarray = GRID) -> dict:
    """Mean ± 1 std (ddof 1) across seeds of `y` over `x` on `grid`, clipped to [0, 1]; `extra`
    columns (e.g. the threshold, for colouring) are averaged on the same grid."""
    if not curves:
        raise ValueError("mean_curve needs at least one curve")
    stacks = {k: [] for k in (y, *extra)}
    for c in curves:
        for k, v in zip(stacks, resample(c[x], [c[k] for k in stacks], grid)):
            stacks[k].append(v)
    ys = np.stack(stacks[y])
    mean = ys.mean(0)
    std = ys.std(0, ddof=1) if len(ys) > 1 else np.zeros_like(mean)
    out = {"x": grid, "mean": mean, "std": std, "lower": np.clip(mean - std, 0, 1),
           "upper": np.clip(mean + std, 0, 1)}
    out.update({k: np.stack(stacks[k]).mean(0) for k in extra})
    return out
