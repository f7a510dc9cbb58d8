"""Per-marker metrics pooled over central-frame markers (SPEC §11).

Predictions are positive when prob >= threshold (quirk 25: the reference mixes > and >=; immaterial).
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.metrics import (average_precision_score, confusion_matrix, f1_score, jaccard_score,
                             matthews_corrcoef, precision_score, recall_score, roc_auc_score)


def _check(probs, labels) -> tuple[np.ndarray, np.ndarray]:
    probs, labels = np.asarray(probs, np.float64).ravel(), np.asarray(labels).ravel().astype(bool)
    if probs.shape != labels.shape:
        raise ValueError(f"probs and labels differ in size: {probs.shape} vs {labels.shape}")
    if probs.size == 0:
        raise ValueError("no predictions to score (empty probs)")
    return probs, labels


def confusion(probs, labels, threshold: float = 0.5) -> dict:
    probs, labels = _check(probs, labels)
    tn, fp, fn, tp = confusion_matrix(labels, probs >= threshold, labels=[False, True]).ravel()
    return {"tp": int(tp), "fp": int(fp), "fn": int(fn), "tn": int(tn)}


def iou(pred: np.ndarray, truth: np.ndarray) -> float:
    """Intersection over union of two boolean masks; an empty union counts as 1."""
    return float(jaccard_score(np.ravel(truth), np.ravel(pred), zero_division=1.0))


def _mcc(labels: np.ndarray, pred: np.ndarray) -> float:
    """sklearn's MCC (0 for a zero denominator); quiet when one class is absent, which is expected here."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "A single label was found", UserWarning)
        return float(matthews_corrcoef(labels, pred))


def marker_metrics(probs, labels, threshold: float = 0.5) -> dict:
    """TP/FP/FN/TN, MCC (0 for a zero denominator), F1, precision, recall, FG/BG IoU at `threshold`,
    AP and AUROC (sklearn; NaN when only one class is present), chance (positive rate), lift = AP/chance."""
    probs, labels = _check(probs, labels)
    c = confusion(probs, labels, threshold)
    pred = probs >= threshold
    two_classes = 0 < labels.sum() < labels.size
    ap = float(average_precision_score(labels, probs)) if two_classes else float("nan")
    auroc = float(roc_auc_score(labels, probs)) if two_classes else float("nan")
    chance = float(labels.mean())
    return {
        **c,
        "mcc": _mcc(labels, pred),
        "f1": float(f1_score(labels, pred, zero_division=0.0)),
        "precision": float(precision_score(labels, pred, zero_division=0.0)),
        "recall": float(recall_score(labels, pred, zero_division=0.0)),
        "fg_iou": iou(pred, labels),
        "bg_iou": iou(~pred, ~labels),
        "ap": ap,
        "auroc": auroc,
        "chance": chance,
        "lift": ap / chance if chance > 0 else float("nan"),
        "n_nodes": int(labels.size),
        "n_pos": int(labels.sum()),
    }
