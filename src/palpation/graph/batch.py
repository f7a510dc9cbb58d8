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
    feats = stats.apply(features)
    b = len(markers)

    def t(a, dtype=torch.float32):
        # torch needs writable memory; np.require copies only read-only or broadcast views
        return torch.as_tensor(np.require(a, requirements=["C", "W"]), dtype=dtype).to(device)

    frame = np.repeat(np.arange(topo.clip_len), markers.shape[2])
    return Data(
        x=t(feats.x.reshape(-1, feats.x.shape[-1])),
        edge_index=t(topo.batched_edge_index(b), torch.long),
        edge_attr_spatial=t(feats.spatial.reshape(-1, 5)),
        edge_attr_temporal=t(feats.temporal.reshape(-1, 7)),
        edge_attr_global_temporal=t(feats.global_temporal.reshape(-1, 2)),
        num_global=b * topo.clip_len,
        num_global_spatial=b * topo.counts["global_spatial"],
        y=t(labels.reshape(-1)),
        frame=t(np.tile(frame, b), torch.long),
        pos=t(feats.pos.reshape(-1, 2)),
        clip_len=topo.clip_len,
    )
