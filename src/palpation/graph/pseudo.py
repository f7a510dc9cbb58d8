"""Training clips with pseudo-labels beside labelled ones (self-training, docs/transfer.md).

A pseudo-labelled real set keeps its markers and gets label *codes* instead of its labels: 0 / 1 a label as
before, PSEUDO + 0 / 1 a pseudo-label, NO_LABEL a marker the teachers did not agree on (or a frame they never
scored). The codes travel where labels travel (gather, rotation, the batch's `y`), so the batch pipeline and the
seeds' batch workers need no field of their own; the loss (model.train.masked_focal_loss) reads them back as
targets and weights, and the focal alpha counts labelled markers only. Labelled sets hold 0 / 1 alone, which the
codes leave as they were.
"""

from __future__ import annotations

import numpy as np

NO_LABEL = -1
PSEUDO = 2  # a pseudo-label's code is PSEUDO + label


def label_counts(labels: np.ndarray) -> tuple[int, int]:
    """(positive, labelled) markers among label codes; for plain 0 / 1 labels (nonzero, size)."""
    labels = np.asarray(labels)
    return int(np.count_nonzero((labels == 1) | (labels == PSEUDO + 1))), int(np.count_nonzero(labels >= 0))


def pseudo_codes(labels: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """int8 codes of agreed pseudo-labels: PSEUDO + label where `keep`, NO_LABEL elsewhere."""
    return np.where(keep, PSEUDO + np.asarray(labels, np.int8), NO_LABEL).astype(np.int8)


class ClipSets:
    """Several clip sets as one training set (Sim clips then pseudo-labelled real clips): what the training reads
    of a ClipSet, `len` and `gather`, with every clip's arrays from its own set (its stride, windows, labels)."""

    def __init__(self, parts: list):
        if not parts:
            raise ValueError("ClipSets needs at least one clip set")
        self.parts = list(parts)
        self.offsets = np.cumsum([0] + [len(p) for p in self.parts])

    def __len__(self) -> int:
        return int(self.offsets[-1])

    def gather(self, idx: np.ndarray, rotations: np.ndarray | None = None, consistent: bool = False,
               scales: np.ndarray | None = None, lattice: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """ClipSet.gather over the sets, clips in `idx` order; a clip's rotation and scale go with it."""
        idx = np.asarray(idx, np.int64)
        if len(idx) and (idx.min() < 0 or idx.max() >= len(self)):
            raise IndexError(f"clip index out of range 0..{len(self) - 1}")
        part = np.searchsorted(self.offsets[1:], idx, side="right")
        markers, labels = None, None
        for p in np.unique(part):
            sel = part == p
            m, lab = self.parts[p].gather(idx[sel] - self.offsets[p], None if rotations is None else
                                          np.asarray(rotations)[sel], consistent,
                                          None if scales is None else np.asarray(scales)[sel], lattice)
            if markers is None:
                markers = np.empty((len(idx), *m.shape[1:]), m.dtype)
                labels = np.empty((len(idx), *lab.shape[1:]), lab.dtype)
            markers[sel], labels[sel] = m, lab
        return markers, labels
