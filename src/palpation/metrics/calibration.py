"""Post-hoc score calibration and its measures (issue 15): temperature or Platt scaling of the logit,
fitted on the training domain's validation split, expected calibration error and reliability bins.

A calibrated score of 0.5 means "more likely than not". Temperature scaling (z / T) keeps the
ranking and the 0.5 point; a shift (z + b) moves only the 0.5 point; Platt scaling (a·z + b, a logistic regression on the logit)
also moves the 0.5 point, which the focal loss's α shifts (α ≈ 0.96 weighs positives 24×); both are
fitted by maximum likelihood with scipy, the Platt slope kept positive.

Cross-fitting between real sets (`cross_fit`, docs/recipe.md "Cross-fitted calibration"): a model deployed on
one real set is calibrated on the same model's scores on another labelled real set, never on its own.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import minimize, minimize_scalar

EPS = 1e-7  # float32 sigmoids saturate to exactly 0/1; clip before taking the logit
N_BINS = 15


def logit(probs) -> np.ndarray:
    p = np.clip(np.asarray(probs, np.float64), EPS, 1 - EPS)
    return np.log(p) - np.log1p(-p)


@dataclass(frozen=True)
class Calibrator:
    """calibrated = sigmoid(scale · logit(p) + shift); identity for method 'none'."""

    method: str = "none"
    scale: float = 1.0
    shift: float = 0.0
    n_fit: int = 0

    def apply(self, probs) -> np.ndarray:
        if self.method == "none":
            return np.asarray(probs, np.float32)
        z = self.scale * logit(probs) + self.shift
        return (1.0 / (1.0 + np.exp(-z))).astype(np.float32)

    def to_dict(self) -> dict:
        return asdict(self)


def _nll(z: np.ndarray, y: np.ndarray) -> float:
    # -[y log s(z) + (1 - y) log(1 - s(z))] = logaddexp(0, z) - y z, stable for large |z|
    return float(np.mean(np.logaddexp(0.0, z) - y * z))


def fit_calibrator(probs, labels, method: str) -> Calibrator:
    """Fit on validation scores; needs both classes (a split without positives cannot calibrate)."""
    probs, y = np.asarray(probs, np.float64).ravel(), np.asarray(labels).ravel().astype(np.float64)
    if method == "none":
        return Calibrator()
    if probs.shape != y.shape or probs.size == 0:
        raise ValueError(f"calibration needs matching non-empty scores and labels, got {probs.shape} and {y.shape}")
    if not 0 < y.sum() < y.size:
        raise ValueError(f"calibration '{method}' needs both classes in the validation split "
                         f"({int(y.sum())} positives of {y.size}); use more validation clips or calibration=none")
    z = logit(probs)
    if method == "temperature":
        res = minimize_scalar(lambda log_t: _nll(z / np.exp(log_t), y), bounds=(-5.0, 5.0), method="bounded",
                              options={"xatol": 1e-6})
        return Calibrator("temperature", float(np.exp(-res.x)), 0.0, int(y.size))
    if method == "platt":  # a > 0 keeps the ranking (a validation split that disagrees cannot invert it)
        res = minimize(lambda ab: _nll(ab[0] * z + ab[1], y), x0=np.array([1.0, 0.0]), method="L-BFGS-B",
                       bounds=[(1e-3, 1e3), (-50.0, 50.0)], options={"ftol": 1e-12, "gtol": 1e-9})
        return Calibrator("platt", float(res.x[0]), float(res.x[1]), int(y.size))
    if method == "shift":  # intercept only (a prior shift in logit): keeps the slope the scores already have
        res = minimize_scalar(lambda b: _nll(z + b, y), bounds=(-50.0, 50.0), method="bounded", options={"xatol": 1e-9})
        return Calibrator("shift", 1.0, float(res.x), int(y.size))
    raise ValueError(f"unknown calibration method '{method}': use none, temperature, platt or shift")


def reliability(probs, labels, n_bins: int = N_BINS) -> dict:
    """Equal-width bins over [0, 1]: mean score (confidence), positive share (accuracy) and count per bin."""
    p, y = np.asarray(probs, np.float64).ravel(), np.asarray(labels).ravel().astype(np.float64)
    if p.shape != y.shape or p.size == 0:
        raise ValueError(f"reliability needs matching non-empty scores and labels, got {p.shape} and {y.shape}")
    edges = np.linspace(0.0, 1.0, n_bins + 1)
    idx = np.clip(np.digitize(p, edges[1:-1], right=False), 0, n_bins - 1)
    count = np.bincount(idx, minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        conf = np.bincount(idx, weights=p, minlength=n_bins) / count
        freq = np.bincount(idx, weights=y, minlength=n_bins) / count
    return {"edges": edges, "confidence": conf, "frequency": freq, "count": count}


def ece(probs, labels, n_bins: int = N_BINS) -> float:
    """Expected calibration error: Σ_b n_b/N · |positive share_b − mean score_b| (binary, equal-width bins)."""
    r = reliability(probs, labels, n_bins)
    used = r["count"] > 0
    gap = np.abs(r["frequency"][used] - r["confidence"][used])
    return float(np.sum(r["count"][used] * gap) / r["count"].sum())


def brier(probs, labels) -> float:
    """Mean squared error of the scores against the 0/1 labels."""
    p, y = np.asarray(probs, np.float64).ravel(), np.asarray(labels).ravel().astype(np.float64)
    if p.shape != y.shape or p.size == 0:
        raise ValueError(f"brier needs matching non-empty scores and labels, got {p.shape} and {y.shape}")
    return float(np.mean((p - y) ** 2))


def cross_fit(scores: dict[str, tuple], partners: dict[str, str | None], method: str = "platt"
              ) -> dict[str, Calibrator | None]:
    """Per set X, the calibrator fitted on the same model's (probs, labels) on `partners[X]`, never on X:
    X's own labels cannot change its calibration. A set whose partner is None gets None (no other set to
    fit on: the caller keeps the calibration it has). `scores` needs every named partner."""
    out = {}
    for name, other in partners.items():
        if other is None:
            out[name] = None
            continue
        if other == name:
            raise ValueError(f"cross_fit: set '{name}' is its own partner; a set must be calibrated on another "
                             "set's scores (use null where there is none)")
        if other not in scores:
            raise ValueError(f"cross_fit: partner '{other}' of '{name}' has no scores; have {sorted(scores)}")
        out[name] = fit_calibrator(*scores[other], method)
    return out


def positive_share(probs, threshold: float = 0.5) -> float:
    """Share of scores called positive at `threshold` (the issue's 'pos_share_05')."""
    return float(np.mean(np.asarray(probs) >= threshold))
