"""The seeds of one configuration as an ensemble (issue 15): per-item mean and spread, the items it is
unsure about, and the coverage-precision curve of the items it commits to.

An item is a marker (pooled central-frame scores) or a map pixel. A committed item is called positive
when the ensemble mean reaches the threshold (0.5: "more likely than not" once scores are calibrated);
the certainty of an item is its margin from the threshold less the seeds' spread, so an item whose seed
interval (mean ± 1 std) straddles the threshold is unsure.
"""

from __future__ import annotations

import numpy as np

COVERAGES = (1.0, 0.8, 0.6, 0.4)


def ensemble(scores) -> tuple[np.ndarray, np.ndarray]:
    """(S, ...) seed scores -> mean and sample std (ddof 1; 0 for one seed) over seeds."""
    s = np.asarray(scores, np.float64)
    if s.ndim < 1 or len(s) == 0:
        raise ValueError("an ensemble needs at least one seed's scores")
    spread = s.std(axis=0, ddof=1) if len(s) > 1 else np.zeros(s.shape[1:])
    return s.mean(axis=0), spread


def certainty(mean: np.ndarray, spread: np.ndarray, threshold: float = 0.5) -> np.ndarray:
    """Margin from the threshold less the spread; < 0 where mean ± spread straddles the threshold."""
    return np.abs(np.asarray(mean) - threshold) - np.asarray(spread)


def unsure(mean: np.ndarray, spread: np.ndarray, threshold: float = 0.5) -> np.ndarray:
    return certainty(mean, spread, threshold) < 0


def committed(cert: np.ndarray, coverage: float) -> np.ndarray:
    """The `coverage` share of items with the highest certainty (ties broken by item order)."""
    if not 0 < coverage <= 1:
        raise ValueError(f"coverage must be in (0, 1], got {coverage}")
    cert = np.asarray(cert).ravel()
    n = int(round(coverage * cert.size))
    keep = np.zeros(cert.size, bool)
    keep[np.argsort(-cert, kind="stable")[:n]] = True
    return keep


def coverage_curve(mean, spread, truth, threshold: float = 0.5, coverages=COVERAGES,
                   truth_near=None, pred_near=None) -> list[dict]:
    """Per coverage: precision of the committed positive items and recall of all true items.

    truth_near / pred_near: optional functions mask -> mask that grow a mask by a tolerance (map pixels,
    mapping.uncertainty); without them a hit is the same item."""
    mean, spread = np.asarray(mean, np.float64).ravel(), np.asarray(spread, np.float64).ravel()
    truth = np.asarray(truth, bool).ravel()
    if not mean.shape == spread.shape == truth.shape:
        raise ValueError(f"mean, spread and truth differ in size: {mean.shape}, {spread.shape}, {truth.shape}")
    cert, pos = certainty(mean, spread, threshold), mean >= threshold
    rows = []
    for cov in coverages:
        pred = pos & committed(cert, cov)
        hit = pred & (truth_near(truth) if truth_near else truth)
        found = truth & (pred_near(pred) if pred_near else pred)
        rows.append({"coverage": float(cov), "precision": float(hit.sum() / pred.sum()) if pred.any() else float("nan"),
                     "recall": float(found.sum() / truth.sum()) if truth.any() else float("nan"),
                     "n_committed": int(round(cov * mean.size)), "n_pred": int(pred.sum())})
    return rows
