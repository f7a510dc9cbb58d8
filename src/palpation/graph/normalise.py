"""z-score normalisation of clip features and the focal-loss α (SPEC §8.3, §10, quirk 7).

Only node columns 0-2 (x, y, dist) and spatial/temporal edge columns 0-2 (dist, dx, dy) are scaled.
The statistics come from augmented training clips (`sample`: one batch of them, as the reference;
`full`: every training clip), are saved in the checkpoint, and the training domain's statistics
always normalise the test domain.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from palpation.graph.features import ClipFeatures
from palpation.graph.pseudo import label_counts

N_SCALED = 3
GROUPS = ("node", "spatial", "temporal")


@dataclass(frozen=True)
class NormStats:
    node_mean: tuple
    node_std: tuple
    spatial_mean: tuple
    spatial_std: tuple
    temporal_mean: tuple
    temporal_std: tuple
    alpha: float  # N_neg / (N_neg + N_pos) over every labelled marker of every frame of the clips
    n_clips: int
    mode: str
    remove_common_motion: bool = False  # the features' input transform (graph.features), kept with the statistics

    @classmethod
    def from_chunks(cls, chunks: Iterable[tuple[ClipFeatures, np.ndarray]], mode: str,
                    remove_common_motion: bool = False) -> "NormStats":
        """Accumulate statistics over (features, labels (B, L, 127)) chunks in float64.

        std is the sample std (ddof 1, as torch's default); a constant column gets std 1.
        """
        sums = {g: np.zeros((3, N_SCALED)) for g in GROUPS}  # count, sum, sum of squares
        n_pos = n_all = n_clips = 0
        for feats, labels in chunks:
            for g, arr in zip(GROUPS, (feats.x, feats.spatial, feats.temporal)):
                cols = arr[..., :N_SCALED].reshape(-1, N_SCALED).astype(np.float64)
                sums[g] += [np.full(N_SCALED, len(cols)), cols.sum(0), (cols ** 2).sum(0)]
            pos, labelled = label_counts(labels)  # pseudo-label codes: unlabelled markers not counted
            n_pos += pos
            n_all += labelled
            n_clips += len(feats.x)
        if n_clips == 0:
            raise ValueError("normalisation statistics need at least one training clip; got none")
        if n_all == 0:  # only with pseudo-labels: every marker of the drawn clips without an agreed label
            raise ValueError(f"the focal alpha needs labelled markers; the {n_clips} normalisation clips have none "
                             "(pseudo-labelled clips without agreed labels): use recipe.norm_stats=full or a laxer "
                             "recipe.pseudo_min_agree / pseudo_margin")
        out = {}
        for g in GROUPS:
            count, total, squares = sums[g]
            if count[0] == 0:  # no edges of this type (e.g. temporal at L = 1)
                mean, std = np.zeros(N_SCALED), np.ones(N_SCALED)
            else:
                mean = total / count
                var = (squares - count * mean ** 2) / np.maximum(count - 1, 1)
                std = np.sqrt(np.maximum(var, 0.0))
                std = np.where(std > 1e-12, std, 1.0)
            out[f"{g}_mean"], out[f"{g}_std"] = tuple(map(float, mean)), tuple(map(float, std))
        return cls(**out, alpha=(n_all - n_pos) / n_all, n_clips=n_clips, mode=mode,
                   remove_common_motion=remove_common_motion)

    def apply(self, feats: ClipFeatures) -> ClipFeatures:
        """A normalised copy; `pos` stays in raw px for the vessel map."""
        return dataclasses.replace(
            feats,
            x=self._scale(feats.x, self.node_mean, self.node_std),
            spatial=self._scale(feats.spatial, self.spatial_mean, self.spatial_std),
            temporal=self._scale(feats.temporal, self.temporal_mean, self.temporal_std),
        )

    def invert(self, feats: ClipFeatures) -> ClipFeatures:
        return dataclasses.replace(
            feats,
            x=self._scale(feats.x, self.node_mean, self.node_std, inverse=True),
            spatial=self._scale(feats.spatial, self.spatial_mean, self.spatial_std, inverse=True),
            temporal=self._scale(feats.temporal, self.temporal_mean, self.temporal_std, inverse=True),
        )

    @staticmethod
    def _scale(arr: np.ndarray, mean, std, inverse: bool = False) -> np.ndarray:
        out = np.array(arr, dtype=np.float32, copy=True)
        m, s = np.asarray(mean, np.float32), np.asarray(std, np.float32)
        out[..., :N_SCALED] = out[..., :N_SCALED] * s + m if inverse else (out[..., :N_SCALED] - m) / s
        return out

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "NormStats":
        fields = {f.name for f in dataclasses.fields(cls)}
        missing = {f.name for f in dataclasses.fields(cls) if f.default is dataclasses.MISSING} - set(d)
        if missing:
            raise ValueError(f"normalisation statistics lack {sorted(missing)}; was the checkpoint "
                             "written by palpation.model.train?")
        return cls(**{k: (tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in d.items() if k in fields})
