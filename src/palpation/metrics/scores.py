"""`scores.npz`, the test scores of one training run (SPEC §10, §11), written by palpation.model.job.

probs (n x 127,) float32 and labels int8: the central-frame markers pooled in clip order, 127 per clip;
sequence (n,) and frame (n,) int64: each clip's central frame, as an index into the test set's sequences
(in the order palpation.graph.sources.load_dataset returns them) and a frame of that sequence, from
`ClipSet.central_frames`. Readers take the ids from here instead of re-deriving the window rule.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from palpation.io import save_npz
from palpation.readers import read_npz
from palpation.markers.lattice import N_MARKERS


@dataclass(frozen=True)
class Scores:
    probs: np.ndarray  # (n * 127,) float32
    labels: np.ndarray  # (n * 127,) int8
    sequence: np.ndarray  # (n,) int64, index into the test set's sequences
    frame: np.ndarray  # (n,) int64, the clip's central frame in that sequence


def save_scores(path: str | Path, scores: Scores) -> None:
    save_npz(path, probs=scores.probs, labels=scores.labels, sequence=scores.sequence, frame=scores.frame)


def load_scores(path: str | Path) -> Scores:
    """One run's scores, checked: present, non-empty, one (sequence, frame) per 127 scores."""
    fix = "rerun the train rule (palpation.apps.train) for this run"
    z = read_npz(path, ("probs", "labels"), fix)
    if "sequence" not in z or "frame" not in z:
        raise ValueError(f"{path}: no (sequence, frame) ids (written before scores carried them); {fix}")
    probs, labels = z["probs"].astype(np.float32).ravel(), z["labels"].astype(np.int8).ravel()
    sequence, frame = z["sequence"].astype(np.int64).ravel(), z["frame"].astype(np.int64).ravel()
    if probs.size == 0:
        raise ValueError(f"{path}: empty prediction set (0 scores); re-run the evaluation of this configuration")
    if probs.shape != labels.shape:
        raise ValueError(f"{path}: probs {probs.shape} and labels {labels.shape} differ in length")
    if sequence.shape != frame.shape or probs.size != N_MARKERS * len(sequence):
        raise ValueError(f"{path}: {probs.size} scores but {len(sequence)} sequence and {len(frame)} frame ids "
                         f"(need {N_MARKERS} scores per id); rerun the train rule for this run")
    return Scores(probs, labels, sequence, frame)
