"""Pseudo-labels from a seed ensemble's scores of unlabelled real clips, kept only where the seeds agree
(self-training filtered by agreement, docs/transfer.md). A label is kept for a marker when at least `min_agree` of
the seeds call it the same side of `threshold`, each at least `margin` away from it; the rest are left out (no
label, not a negative). Reads scores only: the set's labels, if it has any, are never used.
"""

from __future__ import annotations

import numpy as np

from palpation.metrics.scores import Scores


def agreed_labels(seed_probs, threshold: float = 0.5, min_agree: float = 1.0,
                  margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(S, N) seed scores -> (labels int8 (N,), keep bool (N,)): the side of `threshold` that at least `min_agree`
    of the seeds (a share in (0.5, 1]) call with a confidence of at least `margin` each."""
    p = np.asarray(seed_probs, np.float64)
    if p.ndim != 2 or len(p) < 2:
        raise ValueError(f"pseudo-labels need the scores of at least 2 seeds as (seeds, markers), got {p.shape}")
    if not 0.5 < min_agree <= 1 or not 0 <= margin < 0.5 or not 0 < threshold < 1:
        raise ValueError(f"min_agree {min_agree} must be in (0.5, 1], margin {margin} in [0, 0.5), threshold "
                         f"{threshold} in (0, 1)")
    sure = np.abs(p - threshold) >= margin
    pos = ((p >= threshold) & sure).mean(0) >= min_agree
    neg = ((p < threshold) & sure).mean(0) >= min_agree
    return pos.astype(np.int8), pos | neg


def ensemble_pseudo_labels(scores: list[Scores], **rule) -> tuple[np.ndarray, np.ndarray]:
    """`agreed_labels` of several seeds' scores of the same clips (their (sequence, frame) ids must match)."""
    first = scores[0]
    if any(not (np.array_equal(s.sequence, first.sequence) and np.array_equal(s.frame, first.frame))
           for s in scores[1:]):
        raise ValueError("pseudo-labels: the seeds' scores are of different clips (sequence, frame ids differ)")
    return agreed_labels(np.stack([s.probs for s in scores]), **rule)
