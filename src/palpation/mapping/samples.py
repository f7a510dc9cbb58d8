"""Which frame each pooled score belongs to: the (sequence, frame) ids stored with the scores.

`scores.npz` (palpation.metrics.scores) holds `probs` and `labels` of the central-frame markers pooled in
clip order, 127 markers per clip, and each clip's central frame as `sequence` (an index into the test
set's sequences, in the training loader's order, which the map sources share) and `frame`. The window
rule that chose those frames lives in palpation.graph.clips only. The scores' labels are compared with
the dataset's labels at those frames, so scores of another dataset, split or order are caught instead
of mapping predictions onto the wrong frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from palpation.markers.lattice import N_MARKERS

MAX_LABEL_MISMATCH = 0.01  # Sim labels are recomputed at load time; real labels must agree exactly


@dataclass
class Samples:
    """Per central frame: its sequence and frame, the 127 marker pixels, probabilities and labels."""

    seq: np.ndarray  # (n,)
    frame: np.ndarray  # (n,)
    pixels: np.ndarray  # (n, 127, 2) sensor px
    probs: np.ndarray  # (n, 127)
    labels: np.ndarray  # (n, 127) int8

    def __len__(self) -> int:
        return len(self.seq)

    def subset(self, keep: np.ndarray) -> "Samples":
        return Samples(self.seq[keep], self.frame[keep], self.pixels[keep], self.probs[keep], self.labels[keep])


def align(probs: np.ndarray, labels: np.ndarray, sequence: np.ndarray, frame: np.ndarray, markers: list,
          seq_labels: list | None, source: str = "scores") -> Samples:
    """Attach pooled scores to their central frames of `markers` (list of (T, 127, 2) sequences).

    sequence, frame: the scores' ids, one per clip. seq_labels: the dataset's (T, 127) labels per
    sequence, checked against the scores' labels.
    """
    probs, labels = np.asarray(probs).ravel(), np.asarray(labels).ravel()
    seq, frame = np.asarray(sequence, np.int64).ravel(), np.asarray(frame, np.int64).ravel()
    if probs.size == 0:
        raise ValueError(f"{source}: empty prediction set; nothing to map (re-run the evaluation)")
    if probs.size != len(seq) * N_MARKERS or len(seq) != len(frame):
        raise ValueError(f"{source}: {probs.size} scores for {len(seq)} sequence and {len(frame)} frame ids "
                         f"(need {N_MARKERS} per id); rerun the train rule for this run")
    lengths = np.array([len(m) for m in markers], np.int64)
    outside = (seq < 0) | (seq >= len(lengths))
    outside[~outside] = (frame[~outside] < 0) | (frame[~outside] >= lengths[seq[~outside]])
    if outside.any():
        i = int(np.argmax(outside))
        raise ValueError(f"{source}: {int(outside.sum())} score ids lie outside the {len(lengths)} test sequences "
                         f"(e.g. sequence {seq[i]}, frame {frame[i]}); the scores come from another dataset or split")
    pixels = np.stack([markers[s][f] for s, f in zip(seq, frame)]).astype(np.float64)
    samples = Samples(seq, frame, pixels, probs.reshape(-1, N_MARKERS).astype(np.float32),
                      labels.reshape(-1, N_MARKERS).astype(np.int8))
    if seq_labels is not None:
        ref = np.stack([seq_labels[s][f] for s, f in zip(seq, frame)])
        mismatch = float(np.mean(ref != samples.labels))
        if mismatch > MAX_LABEL_MISMATCH:
            raise ValueError(f"{source}: the scores' labels differ from the dataset's at {100 * mismatch:.1f} % "
                             f"of their central-frame markers; the scores come from another dataset, split or "
                             f"order")
    return samples
