"""Which frame each pooled score belongs to: the test set's central frames, rebuilt with the clip set.

`scores.npz` (palpation.model.job) holds `probs` and `labels` of the central-frame markers pooled in
clip order: sequences in test-set order, windows in `ClipSet.windows` order, 127 markers per clip. We
rebuild the same windows by building a `palpation.graph.clips.ClipSet` over the same sequences, so the
rule lives in one place. A window (seq, start) has its central frame at start + d * (L // 2):
* Silicone (d = 1, L = 5, windows inside the video): central frames 2..13 of each 16-frame video;
* Meat (`window="centred"`: the set holds only the reference's central frames): every frame;
* Sim (d = 24, L = 5): starts 0, 24, ..., 192, central frames 48, 72, ..., 240.
The scores' labels are compared with the dataset's labels at the rebuilt frames, so a different clip
length, split or order is caught instead of mapping predictions onto the wrong frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from palpation.graph.clips import ClipSet
from palpation.graph.layout import rest_layout
from palpation.graph.sources import Sequences
from palpation.io import read_npz
from palpation.markers.lattice import N_MARKERS

MAX_LABEL_MISMATCH = 0.01  # Sim labels are recomputed at load time; real labels must agree exactly
_REST = rest_layout("ideal")  # ClipSet wants a rest layout for its rotations; windows do not use it


def central_frames(lengths, clip_len: int, stride: int, window: str = "full") -> tuple[np.ndarray, np.ndarray]:
    """(sequence index, central frame) of every window, in ClipSet order."""
    if clip_len < 1 or stride < 1:
        raise ValueError(f"clip_len and stride must be >= 1, got {clip_len}, {stride}")
    lengths = [int(n) for n in lengths]
    if not lengths:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    seqs = Sequences("map", list(range(len(lengths))), [np.zeros((n, N_MARKERS, 2), np.float32) for n in lengths],
                     stride, labels=[np.zeros((n, N_MARKERS), np.int8) for n in lengths], window=window)
    windows = ClipSet(seqs, clip_len, _REST).windows
    return windows[:, 0].copy(), windows[:, 1] + stride * (clip_len // 2)


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


def load_scores(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """`probs` (n,) and `labels` (n,) of one evaluation run."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"scores {path} not found; run the train rule for this configuration first")
    z = read_npz(path, ("probs", "labels"), "rerun the train rule for this configuration (palpation.model.job)")
    probs, labels = z["probs"].astype(np.float32).ravel(), z["labels"].astype(np.int8).ravel()
    if probs.size == 0:
        raise ValueError(f"{path}: empty prediction set (0 scores); re-run the evaluation of this configuration")
    if probs.shape != labels.shape:
        raise ValueError(f"{path}: probs {probs.shape} and labels {labels.shape} differ in length")
    return probs, labels


def align(probs: np.ndarray, labels: np.ndarray, markers: list, seq_labels: list | None, clip_len: int,
          stride: int, source: str = "scores", central: tuple | None = None, window: str = "full") -> Samples:
    """Attach pooled scores to the central frames of `markers` (list of (T, 127, 2) sequences).

    seq_labels: the dataset's (T, 127) labels per sequence, checked against the scores' labels.
    central: explicit (seq, frame) per clip (e.g. the dense Sim slide); default: the ClipSet windows
    (`window` as the dataset's Sequences: "full" or "centred").
    """
    probs, labels = np.asarray(probs).ravel(), np.asarray(labels).ravel()
    if probs.size == 0:
        raise ValueError(f"{source}: empty prediction set; nothing to map (re-run the evaluation)")
    if central is None:
        seq, frame = central_frames([len(m) for m in markers], clip_len, stride, window)
    else:
        seq, frame = (np.asarray(a, np.int64) for a in central)
    expected = len(seq) * N_MARKERS
    if probs.size != expected:
        raise ValueError(f"{source}: {probs.size} scores but the test set gives {len(seq)} central frames x "
                         f"{N_MARKERS} = {expected} at clip_len={clip_len}, stride={stride}, window={window}; "
                         f"pass the clip_len and dataset the run was scored with")
    pixels = np.stack([markers[s][f] for s, f in zip(seq, frame)]).astype(np.float64)
    samples = Samples(seq, frame, pixels, probs.reshape(-1, N_MARKERS).astype(np.float32),
                      labels.reshape(-1, N_MARKERS).astype(np.int8))
    if seq_labels is not None:
        ref = np.stack([seq_labels[s][f] for s, f in zip(seq, frame)])
        mismatch = float(np.mean(ref != samples.labels))
        if mismatch > MAX_LABEL_MISMATCH:
            raise ValueError(f"{source}: the scores' labels differ from the dataset's at {100 * mismatch:.1f} % "
                             f"of the rebuilt central-frame markers; the scores come from another dataset, "
                             f"split, order or clip_len")
    return samples
