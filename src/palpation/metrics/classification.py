"""Per-marker metrics pooled over central-frame markers (SPEC §11).

Predictions are positive when prob >= threshold (quirk 25: the reference mixes > and >=; immaterial).
"""

from __future__ import annotations

import math

import numpy as np
from sklearn.metrics import average_precision_score, roc_auc_score


def _check(probs, labels) -> tuple[np.ndarray, np.ndarray]:
    probs, labels = np.asarray(probs, np.float64).ravel(), np.asarray(labels).ravel().astype(bool)
    if probs.shape != labels.shape:
        raise ValueError(f"probs and labels differ in size: {probs.shape} vs {labels.shape}")
    if probs.size == 0:
        raise ValueError("no predictions to score (empty probs)")
    return probs, labels


def confusion(probs, labels, threshold: float = 0.5) -> dict:
    probs, labels = _check(probs, labels)
    pred = probs >= threshold
    return {"tp": int(np.sum(pred & labels)), "fp": int(np.sum(pred & ~labels)),
            "fn": int(np.sum(~pred & labels)), "tn": int(np.sum(~pred & ~labels))}


def iou(pred: np.ndarray, truth: np.ndarray) -> float:
    """Intersection over union of two boolean masks; an empty union counts as 1."""
    union = np.sum(pred | truth)
    return 1.0 if union == 0 else float(np.sum(pred & truth) / union)


def _ratio(num: float, den: float) -> float:
    return float(num / den) if den else 0.0


def marker_metrics(probs, labels, threshold: float = 0.5) -> dict:
    """TP/FP/FN/TN, MCC (0 for a zero denominator), F1, precision, recall, FG/BG IoU at `threshold`,
    AP and AUROC (sklearn; NaN when only one class is present), chance (positive rate), lift = AP/chance."""
    probs, labels = _check(probs, labels)
    c = confusion(probs, labels, threshold)
    tp, fp, fn, tn = c["tp"], c["fp"], c["fn"], c["tn"]
    den = math.sqrt(float(tp + fp) * (tp + fn) * (tn + fp) * (tn + fn))
    precision, recall = _ratio(tp, tp + fp), _ratio(tp, tp + fn)
    pred = probs >= threshold
    two_classes = 0 < labels.sum() < labels.size
    ap = float(average_precision_score(labels, probs)) if two_classes else float("nan")
    auroc = float(roc_auc_score(labels, probs)) if two_classes else float("nan")
    chance = float(labels.mean())
    return {
        **c,
        "mcc": _ratio(tp * tn - fp * fn, den),
        "f1": _ratio(2 * tp, 2 * tp + fp + fn),
        "precision": precision,
        "recall": recall,
        "fg_iou": iou(pred, labels),
        "bg_iou": iou(~pred, ~labels),
        "ap": ap,
        "auroc": auroc,
        "chance": chance,
        "lift": ap / chance if chance > 0 else float("nan"),
        "n_nodes": int(labels.size),
        "n_pos": int(labels.sum()),
    }
