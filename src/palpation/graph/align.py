"""Feature-statistics alignment of a scored domain's clips onto the training domain's (recipe field `align`).

The scaled raw feature columns (`normalise.N_SCALED` of each group: node x, y, dist; spatial and temporal dist,
dx, dy) of unlabelled clips of the scored domain are mapped, per group, onto the first and second moments of the
training domain's clips before the training statistics normalise them:

    f' = (f - mean_t) A + mean_s

* `meanstd`: A = diag(std_s / std_t), per-feature mean and std matching;
* `coral`: A = C_t^(-1/2) C_s^(1/2) (CORAL, Sun et al. 2016, in its target-side form: the scored clips are
  re-coloured to the training covariance instead of the training clips to the scored one, so one training
  serves every scored set), computed on the correlation matrices (each loaded with `RIDGE` on the diagonal) between
  the two sets' column scalings, so columns of very different scales (px positions, edge lengths) keep their own.

Where the scored domain's moments come from is the recipe field `align_stats` (model.config): `other_real`
(the other real set's clips, inductive), `test_set` (the scored set's own clips, transductive) or `test_sequence`
(each scored sequence's own clips: test-time normalisation per sequence, transductive). Labels are never read.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from palpation.graph.clips import ClipSet
from palpation.graph.edges import ClipTopology
from palpation.graph.features import ClipFeatures, clip_features
from palpation.graph.normalise import GROUPS, N_SCALED

METHODS = ("none", "meanstd", "coral")
STATS_FROM = ("other_real", "test_set", "test_sequence")  # the first is inductive, the others transductive
CHUNK = 64  # clips per feature chunk
RIDGE = 1e-4  # diagonal load of both correlation matrices (a constant or collinear column stays finite)
_ARRAYS = {"node": "x", "spatial": "spatial", "temporal": "temporal"}


@dataclass(frozen=True)
class Moments:
    """Per group: column means (3,), covariance (3, 3) and the row count, in float64."""

    mean: dict
    cov: dict
    count: dict

    @classmethod
    def of(cls, chunks: Iterable[ClipFeatures]) -> "Moments":
        sums = {g: [0, np.zeros(N_SCALED), np.zeros((N_SCALED, N_SCALED))] for g in GROUPS}
        for feats in chunks:
            for g in GROUPS:
                cols = getattr(feats, _ARRAYS[g])[..., :N_SCALED].reshape(-1, N_SCALED).astype(np.float64)
                sums[g][0] += len(cols)
                sums[g][1] += cols.sum(0)
                sums[g][2] += cols.T @ cols
        mean, cov = {}, {}
        for g, (n, total, outer) in sums.items():
            if n < 2:
                raise ValueError(f"feature alignment: {n} rows of {g} features; need at least 2 (more clips)")
            mean[g] = total / n
            cov[g] = (outer - n * np.outer(mean[g], mean[g])) / (n - 1)
        return cls(mean, cov, {g: s[0] for g, s in sums.items()})


def _sqrt_psd(c: np.ndarray, inverse: bool = False) -> np.ndarray:
    """Symmetric square root (or inverse square root) of a symmetric positive definite matrix."""
    w, v = np.linalg.eigh((c + c.T) / 2)
    w = np.maximum(w, 1e-12)
    return (v * (w ** (-0.5 if inverse else 0.5))) @ v.T


def _std(c: np.ndarray) -> np.ndarray:
    """Column stds of a covariance; a constant column gets 1, as NormStats gives it."""
    std = np.sqrt(np.maximum(np.diag(c), 0.0))
    return np.where(std > 1e-12, std, 1.0)


def _correlation(c: np.ndarray) -> np.ndarray:
    """The correlation matrix of a covariance, loaded with RIDGE on the diagonal (no column is scaled away)."""
    std = _std(c)
    return c / np.outer(std, std) + RIDGE * np.eye(len(c))


@dataclass(frozen=True)
class GroupMap:
    """f' = (f - shift_in) @ matrix + shift_out, on the first N_SCALED columns of one group."""

    shift_in: np.ndarray
    matrix: np.ndarray
    shift_out: np.ndarray

    def apply(self, arr: np.ndarray) -> np.ndarray:
        out = np.array(arr, dtype=np.float32, copy=True)
        cols = out[..., :N_SCALED].astype(np.float64)
        out[..., :N_SCALED] = ((cols - self.shift_in) @ self.matrix + self.shift_out).astype(np.float32)
        return out


def fit_maps(source: Moments, target: Moments, method: str) -> dict[str, GroupMap]:
    """Per group, the map that gives `target`'s features `source`'s moments (means, and std or covariance)."""
    if method not in METHODS[1:]:
        raise ValueError(f"feature alignment method {method!r}: use one of {list(METHODS[1:])}")
    maps = {}
    for g in GROUPS:
        ds, dt = _std(source.cov[g]), _std(target.cov[g])
        if method == "meanstd":
            matrix = np.diag(ds / dt)
        else:  # D_t^-1 R_t^(-1/2) R_s^(1/2) D_s: C_t^(-1/2) C_s^(1/2) up to the load
            rotate = _sqrt_psd(_correlation(target.cov[g]), inverse=True) @ _sqrt_psd(_correlation(source.cov[g]))
            matrix = (rotate / dt[:, None]) * ds[None, :]
        maps[g] = GroupMap(target.mean[g], matrix, source.mean[g])
    return maps


@dataclass(frozen=True)
class Alignment:
    """Maps for the whole scored set (key None) or one per scored sequence (keys: ClipSet sequence indices)."""

    method: str
    stats_from: str  # other_real | test_set | test_sequence
    maps: dict

    @property
    def transductive(self) -> bool:
        return self.stats_from != "other_real"

    def apply(self, feats: ClipFeatures, sequences: np.ndarray) -> ClipFeatures:
        """Aligned copy of features of clips whose ClipSet sequence indices are `sequences` (one per clip)."""
        sequences = np.asarray(sequences)
        arrays = {name: np.array(getattr(feats, name), np.float32, copy=True) for name in _ARRAYS.values()}
        keys = [None] if None in self.maps else list(dict.fromkeys(sequences.tolist()))
        for key in keys:
            rows = slice(None) if key is None else sequences == key
            if key not in self.maps:
                raise ValueError(f"feature alignment: no statistics for sequence {key}; fitted on other clips")
            for g, name in _ARRAYS.items():
                arrays[name][rows] = self.maps[key][g].apply(arrays[name][rows])
        return dataclasses.replace(feats, **arrays)

    def to_dict(self) -> dict:
        """Plain summary for metrics.json (the whole-set map's matrices; per-sequence maps are only counted)."""
        out = {"method": self.method, "stats_from": self.stats_from, "transductive": self.transductive,
               "n_maps": len(self.maps)}
        if None in self.maps:
            out["maps"] = {g: {"shift_in": m.shift_in.tolist(), "matrix": m.matrix.tolist(),
                               "shift_out": m.shift_out.tolist()} for g, m in self.maps[None].items()}
        return out


def clip_moments(clips: ClipSet, rest: np.ndarray, topo: ClipTopology, remove_common_motion: bool,
                 idx: np.ndarray | None = None) -> Moments:
    """Moments of the unaugmented clips `idx` (all by default) of a clip set; its labels are not read."""
    idx = np.arange(len(clips)) if idx is None else np.asarray(idx)

    def chunks():
        for s in range(0, len(idx), CHUNK):
            markers, _ = clips.gather(idx[s:s + CHUNK])
            yield clip_features(markers, rest, topo, remove_common_motion)

    return Moments.of(chunks())


def fit_alignment(source: Moments, target: ClipSet, rest: np.ndarray, topo: ClipTopology, method: str,
                  stats_from: str, remove_common_motion: bool = False) -> Alignment:
    """The alignment of `target`'s clips (the other real set's for `other_real`, else the scored set's) onto the
    training clips' moments `source` (clip_moments); `test_sequence` fits one map per target sequence from that
    sequence's own clips."""
    if stats_from not in STATS_FROM:
        raise ValueError(f"align_stats={stats_from!r}: use one of {list(STATS_FROM)}")
    if stats_from != "test_sequence":
        return Alignment(method, stats_from,
                         {None: fit_maps(source, clip_moments(target, rest, topo, remove_common_motion), method)})
    seq = target.windows[:, 0]
    return Alignment(method, stats_from, {int(k): fit_maps(source, clip_moments(target, rest, topo, remove_common_motion,
                                                                              np.flatnonzero(seq == k)), method)
                                          for k in np.unique(seq)})
