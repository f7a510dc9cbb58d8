"""Batches of clip graphs as one torch-geometric `Data` (SPEC §8), built in numpy then moved once.

All clips share one topology, so a batch is assembled directly: node rows are [all marker nodes
(clip-major), all global nodes], edges type-major. This replaces PyG's generic collate, which would
copy 5,714 edges per clip through Python objects.
"""

from __future__ import annotations

import numpy as np
import torch
from torch_geometric.data import Data

from palpation.graph.edges import ClipTopology
from palpation.graph.features import ClipFeatures, clip_features
from palpation.graph.normalise import NormStats


# the per-batch arrays of a training step, in the dtype the model takes (what batch workers ship, model.batch_workers)
STEP_FIELDS = ("x", "edge_attr_spatial", "edge_attr_temporal", "edge_attr_global_temporal", "y")


def step_arrays(markers: np.ndarray, labels: np.ndarray, rest: np.ndarray, topo: ClipTopology, stats: NormStats,
                features: ClipFeatures | None = None) -> dict[str, np.ndarray]:
    """The STEP_FIELDS of make_batch as C-contiguous float32 numpy arrays (no torch: batch workers build these)."""
    if features is None:
        features = clip_features(markers, rest, topo, stats.remove_common_motion)
    feats = stats.apply(features)
    flat = {"x": feats.x.reshape(-1, feats.x.shape[-1]), "edge_attr_spatial": feats.spatial.reshape(-1, 5),
            "edge_attr_temporal": feats.temporal.reshape(-1, 7),
            "edge_attr_global_temporal": feats.global_temporal.reshape(-1, 2), "y": labels.reshape(-1)}
    return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in flat.items()}


def global_counts(topo: ClipTopology, n_clips: int) -> dict[str, int]:
    """Global nodes and global-spatial edges of a batch of `n_clips` clips (the model's split of its rows)."""
    return {"num_global": n_clips * topo.clip_len, "num_global_spatial": n_clips * topo.counts["global_spatial"]}


def make_batch(markers: np.ndarray, labels: np.ndarray, rest: np.ndarray, topo: ClipTopology,
               stats: NormStats, device: str | torch.device = "cpu", features: ClipFeatures | None = None) -> Data:
    """markers (B, L, 127, 2) px, labels (B, L, 127) -> normalised batch graph on `device`.

    `features`: clip_features(markers, rest, topo, stats.remove_common_motion) computed already (models with
    other statistics scoring the same clips share them).

    Fields: x (B·127L, F) marker features, edge_index (2, E), edge_attr_spatial/temporal/
    global_temporal, num_global (B·L), num_global_spatial (edges), y (B·127L) labels,
    frame (B·127L) frame index, pos (raw px).
    """
    if features is None:
        features = clip_features(markers, rest, topo, stats.remove_common_motion)
    b = len(markers)

    def t(a, dtype=torch.float32):
        # torch needs writable memory; np.require copies only read-only or broadcast views
        return torch.as_tensor(np.require(a, requirements=["C", "W"]), dtype=dtype).to(device)

    frame = np.repeat(np.arange(topo.clip_len), markers.shape[2])
    return Data(
        **{k: t(v) for k, v in step_arrays(markers, labels, rest, topo, stats, features).items()},
        edge_index=t(topo.batched_edge_index(b), torch.long),
        **global_counts(topo, b),
        frame=t(np.tile(frame, b), torch.long),
        pos=t(features.pos.reshape(-1, 2)),  # raw px: normalising leaves pos alone
        clip_len=topo.clip_len,
    )
