"""Graph topology: spatial k-NN edges on the rest layout and the L-frame clip graph (SPEC §8.1-8.2).

A clip of L frames has 127·L marker nodes (frame-major: node t·127 + i) followed by L global nodes
(node 127·L + t). Edges are directed (row 0 = source, row 1 = target, PyG's source_to_target flow) and
come in four blocks, always in this order: spatial, temporal, global-spatial, global-temporal.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from palpation.markers.lattice import N_MARKERS, RING_SIZES, ring_slice

EDGE_TYPES = ("spatial", "temporal", "global_spatial", "global_temporal")
KNN_K = 7  # including self (SPEC §8.1)


def keep_counts(rest: np.ndarray) -> np.ndarray:
    """Neighbours kept per node: 6 inside ring 6, 4 on ring 6, 3 at its six corners (SPEC §8.1)."""
    rest = _check_rest(rest)
    counts = np.full(N_MARKERS, 6, dtype=np.int64)
    outer = np.arange(N_MARKERS)[ring_slice(len(RING_SIZES) - 1)]
    counts[outer] = 4
    # base-graph order sorts each ring by bearing, so the corners are every 6th marker of ring 6;
    # the phase is the one whose markers lie farthest out (robust to a slightly distorted layout)
    radius = np.linalg.norm(rest[outer] - rest[0], axis=1)
    phase = int(np.argmax([radius[p::6].sum() for p in range(6)]))
    counts[outer[phase::6]] = 3
    return counts


def spatial_edges(rest: np.ndarray) -> np.ndarray:
    """(684, 2) directed (source, target) pairs: each node receives from its c_i nearest rest neighbours.

    k-NN with k = 7 including self; self is dropped and node i keeps its first c_i neighbours by
    distance (ties broken by index, so the result is deterministic). Symmetry is not enforced.
    """
    rest = _check_rest(rest)
    d = np.linalg.norm(rest[:, None, :] - rest[None, :, :], axis=-1)
    counts = keep_counts(rest)
    pairs = []
    for i in range(N_MARKERS):
        order = np.lexsort((np.arange(N_MARKERS), d[i]))[:KNN_K]
        order = order[order != i][: counts[i]]
        pairs.append(np.stack([order, np.full_like(order, i)], axis=1))
    return np.concatenate(pairs).astype(np.int64)


@dataclass(frozen=True)
class ClipTopology:
    """Edges of one clip graph; `edge_index` is (2, E) in the block order of EDGE_TYPES."""

    clip_len: int
    adjacency: np.ndarray  # (684, 2) spatial pairs inside one frame
    edge_index: np.ndarray  # (2, E) int64
    counts: dict  # edge type -> number of edges
    cache: dict = field(default_factory=dict, compare=False, repr=False)  # batch size -> edge index

    @property
    def n_markers(self) -> int:
        return N_MARKERS * self.clip_len

    @property
    def n_nodes(self) -> int:
        return (N_MARKERS + 1) * self.clip_len

    def block(self, edge_type: str) -> slice:
        start = 0
        for name in EDGE_TYPES:
            if name == edge_type:
                return slice(start, start + self.counts[name])
            start += self.counts[name]
        raise ValueError(f"unknown edge type '{edge_type}': use one of {EDGE_TYPES}")

    def batched_edge_index(self, batch_size: int) -> np.ndarray:
        """Edge index of `batch_size` clips, nodes ordered [all marker nodes, all global nodes] and
        edges type-major (all spatial edges of all clips, then temporal, ...). With one clip this is
        exactly the single-clip order; sum aggregation and BatchNorm do not depend on the order."""
        return _batched(self, batch_size)


def clip_topology(adjacency: np.ndarray, clip_len: int) -> ClipTopology:
    """The clip graph of SPEC §8.2 for `clip_len` frames (5,714 edges at L = 5)."""
    if clip_len < 1:
        raise ValueError(f"clip_len must be >= 1, got {clip_len}")
    n, big_l = N_MARKERS, clip_len
    glob = n * big_l  # index of the first global node
    frames = np.arange(big_l)
    markers = np.arange(n)
    spatial = np.concatenate([adjacency.T + t * n for t in frames], axis=1)
    fwd = np.stack([(frames[:-1, None] * n + markers).ravel(), (frames[1:, None] * n + markers).ravel()])
    temporal = np.concatenate([fwd, fwd[::-1]], axis=1)  # all forward edges, then all backward
    to_global = np.stack([np.arange(n * big_l), glob + np.repeat(frames, n)])
    global_spatial = np.concatenate([to_global, to_global[::-1]], axis=1)
    g_fwd = np.stack([glob + frames[:-1], glob + frames[1:]])
    global_temporal = np.concatenate([g_fwd, g_fwd[::-1]], axis=1)
    blocks = dict(zip(EDGE_TYPES, (spatial, temporal, global_spatial, global_temporal)))
    edge_index = np.concatenate(list(blocks.values()), axis=1).astype(np.int64)
    return ClipTopology(clip_len, np.asarray(adjacency, np.int64), edge_index,
                        {k: v.shape[1] for k, v in blocks.items()})


def _batched(topo: ClipTopology, batch_size: int) -> np.ndarray:
    if batch_size not in topo.cache:
        m, big_l = topo.n_markers, topo.clip_len
        b = np.arange(batch_size)[:, None, None]
        parts = []
        for name in EDGE_TYPES:
            ei = topo.edge_index[:, topo.block(name)]
            shifted = np.where(ei >= m, batch_size * m + b * big_l + (ei - m), b * m + ei)
            parts.append(shifted.transpose(1, 0, 2).reshape(2, -1))
        topo.cache[batch_size] = np.concatenate(parts, axis=1)
    return topo.cache[batch_size]


def _check_rest(rest: np.ndarray) -> np.ndarray:
    rest = np.asarray(rest, dtype=np.float64)
    if rest.shape != (N_MARKERS, 2) or not np.all(np.isfinite(rest)):
        raise ValueError(f"rest layout must be finite ({N_MARKERS}, 2) px in base-graph order, got {rest.shape}")
    return rest
