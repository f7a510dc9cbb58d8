"""Windows of L frames over sequences and their gathering into augmented clips (SPEC §8.3).

A window starting at frame s holds frames s, s+d, ..., s+(L-1)d. Sim (d = 24): starts 0, d, 2d, ...
while the window fits in the F//d coarse steps (9 per 317-frame trajectory at L = 5). Real data
(d = 1): every start, 12 per 16-frame Silicone video at L = 5. Sequences marked `centred` (Meat,
which holds only the central frames of the reference's clips) get one window centred on every frame,
frames outside the sequence replaced by the nearest one.
A clip's prediction is for its central frame k = L // 2 (`central_offset`); `ClipSet.central_frames`
gives the (sequence, frame) of each window, the ids stored with the scores (palpation.metrics.scores).
"""

from __future__ import annotations

import numpy as np

from palpation.graph.augment import ROTATION_STEP_DEG, rotate_points, rotation_permutations, sim_labels
from palpation.graph.sources import Sequences


def window_starts(n_frames: int, clip_len: int, stride: int) -> np.ndarray:
    """First frame of every window; Sim uses a start step of `stride` (coarse frames), real data 1."""
    steps = n_frames // stride
    return np.arange(max(steps - clip_len + 1, 0)) * stride


def central_offset(clip_len: int) -> int:
    """Index inside a clip of the frame its prediction is for: k = L // 2 (SPEC §8.3)."""
    return clip_len // 2


class ClipSet:
    """All windows of some sequences; `gather` builds clip arrays with optional rotation."""

    def __init__(self, seqs: Sequences, clip_len: int, rest: np.ndarray):
        self.seqs, self.clip_len = seqs, clip_len
        if seqs.window == "centred":
            half = central_offset(clip_len) * seqs.stride
            rows = [(i, c - half) for i, m in enumerate(seqs.markers) for c in range(len(m))]
        else:
            rows = [(i, s) for i, m in enumerate(seqs.markers)
                    for s in window_starts(len(m), clip_len, seqs.stride)]
        if not rows:
            raise ValueError(f"{seqs.name}: no window of {clip_len} frames at stride {seqs.stride} fits in "
                             f"sequences of {sorted({len(m) for m in seqs.markers})} frames")
        self.windows = np.array(rows, dtype=np.int64)  # (N, 2): sequence index, start frame
        self.rest = np.asarray(rest, np.float32)
        self._perms = rotation_permutations(rest)

    def __len__(self) -> int:
        return len(self.windows)

    def central_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """(sequence index, frame) of every window's central frame, in window order."""
        return self.windows[:, 0].copy(), self.windows[:, 1] + self.seqs.stride * central_offset(self.clip_len)

    def frames(self, seq: int, start: int) -> np.ndarray:
        f = start + self.seqs.stride * np.arange(self.clip_len)
        return np.clip(f, 0, len(self.seqs.markers[seq]) - 1)  # only `centred` windows reach past an end

    def gather(self, idx: np.ndarray, rotations: np.ndarray | None = None,
               consistent: bool = False, scales: np.ndarray | None = None,
               lattice: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Clips `idx` -> markers (B, L, 127, 2) float32 px and labels (B, L, 127) int8.

        rotations: index 0..5 per clip (x 60 deg) or None. Sim labels are computed after rotating.
        consistent: renumber nodes so each sits at its rest site (quirk 14 fixed).
        scales: displacement-magnitude factor per clip or None: markers = rest + s (markers - rest),
        before the rotation, so Sim labels follow the scaled markers (a softer or deeper press).
        lattice: rotate each marker's displacement from its rest site and move it to the site the rotation
        takes it to (rest site + rotated displacement), labels carried with it. The rest layout is not
        6-fold symmetric about the rotation centre (template: sites land 1.8-3.2 px off, up to 16 px), so
        `consistent` adds that static offset to rotated clips only; `lattice` has none (issue 15).
        """
        idx = np.asarray(idx, dtype=np.int64)
        rot = np.zeros(len(idx), np.int64) if rotations is None else np.asarray(rotations, np.int64)
        markers, labels = [], []
        for k, ((seq, start), r) in enumerate(zip(self.windows[idx], rot)):
            f = self.frames(seq, start)
            m = self.seqs.markers[seq][f]
            if scales is not None:
                m = (self.rest + scales[k] * (m - self.rest)).astype(np.float32)
            if lattice:
                m, lab = self._lattice_rotated(seq, f, m, r)
            elif self.seqs.labels is not None:
                lab = self.seqs.labels[seq][f]
                if r:
                    m = rotate_points(m, ROTATION_STEP_DEG * r)
            else:
                line = self.seqs.centreline[seq][f]
                if r:
                    m, line = rotate_points(m, ROTATION_STEP_DEG * r), rotate_points(line, ROTATION_STEP_DEG * r)
                lab = sim_labels(m, line, self.seqs.contact[seq][f])
            if consistent and r and not lattice:
                m, lab = m[:, self._perms[r]], lab[:, self._perms[r]]
            markers.append(m)
            labels.append(lab)
        return np.stack(markers).astype(np.float32), np.stack(labels).astype(np.int8)

    def _lattice_rotated(self, seq: int, f: np.ndarray, m: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray]:
        """(`lattice` mode) markers rest_j + R(m_p(j) - rest_p(j)) and labels lab_p(j), p = the rotation's lattice
        permutation; Sim labels from the unrotated clip (a marker's distance to the vessel does not rotate)."""
        if self.seqs.labels is not None:
            lab = self.seqs.labels[seq][f]
        else:
            lab = sim_labels(m, self.seqs.centreline[seq][f], self.seqs.contact[seq][f])
        if not r:
            return m, lab
        perm = self._perms[r]
        disp = rotate_points(m[:, perm] - self.rest[perm], ROTATION_STEP_DEG * r, centre=(0.0, 0.0))
        return (self.rest + disp).astype(np.float32), lab[:, perm]
