"""Raw node and edge features of clip graphs (SPEC §8.2), vectorised over a batch of clips.

Marker node (137 at L = 5): [x, y] px, rest dist_from_centre, rest unit vector from marker 0
((0, 0) for the centre), 127 id one-hot, L time one-hot. No displacement or velocity features.
Spatial edge: [dist, dx, dy, dx/dist, dy/dist] with vec = p[dst] - p[src], dist >= 1e-6.
Temporal edge: the same 5 across frames + direction one-hot (forward [0, 1], backward [1, 0]).
Global-temporal edge: the direction one-hot. Global nodes and global-spatial edges have none.
With `remove_common_motion` (an opt-in recipe field, off in every shipped recipe) the features see each frame's
markers without the whole field's translation (`without_common_motion`); `pos` stays raw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from palpation.graph.edges import ClipTopology
from palpation.markers.lattice import N_MARKERS

MIN_DIST = 1e-6
FORWARD, BACKWARD = (0.0, 1.0), (1.0, 0.0)


def marker_feature_dim(clip_len: int) -> int:
    return 2 + 1 + 2 + N_MARKERS + clip_len


@dataclass
class ClipFeatures:
    """Features of B clips; rows follow the single-clip order of ClipTopology, clip-major."""

    x: np.ndarray  # (B, 127·L, 5 + 127 + L) marker node features
    spatial: np.ndarray  # (B, E_s, 5)
    temporal: np.ndarray  # (B, E_t, 7)
    global_temporal: np.ndarray  # (B, E_gt, 2)
    pos: np.ndarray  # (B, 127·L, 2) raw marker px (kept for vessel maps, not a model input)


def static_marker_features(rest: np.ndarray) -> np.ndarray:
    """(127, 3): rest distance from marker 0 and the unit vector from marker 0 ((0, 0) at the centre)."""
    offset = np.asarray(rest, np.float64) - np.asarray(rest, np.float64)[0]
    dist = np.linalg.norm(offset, axis=1)
    unit = np.divide(offset, dist[:, None], out=np.zeros_like(offset), where=dist[:, None] > 0)
    return np.concatenate([dist[:, None], unit], axis=1).astype(np.float32)


def without_common_motion(markers: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Markers (..., 127, 2) px with each frame's mean displacement from the rest sites taken off: the whole
    field's translation goes (the real slides' trial-specific drift that no twin reproduces, docs/loop.md "What a
    held-out slide MAE can reach"), every marker's motion relative to the others (the vessel's cue) stays."""
    markers = np.asarray(markers, np.float32)
    return markers - (markers - np.asarray(rest, np.float32)).mean(axis=-2, keepdims=True)


def _edge_geometry(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    vec = dst - src
    dist = np.maximum(np.linalg.norm(vec, axis=-1, keepdims=True), MIN_DIST)
    return np.concatenate([dist, vec, vec / dist], axis=-1)


def clip_features(markers: np.ndarray, rest: np.ndarray, topo: ClipTopology,
                  remove_common_motion: bool = False) -> ClipFeatures:
    """Features of clips `markers` (B, L, 127, 2) px (or one clip (L, 127, 2)) on topology `topo`."""
    markers = np.asarray(markers, np.float32)
    if markers.ndim == 3:
        markers = markers[None]
    b, big_l = markers.shape[:2]
    if markers.shape[1:] != (topo.clip_len, N_MARKERS, 2):
        raise ValueError(f"clips must be (B, {topo.clip_len}, {N_MARKERS}, 2) px, got {markers.shape}")
    if not np.all(np.isfinite(markers)):
        raise ValueError("clip markers contain NaN/inf; fill missing markers before building graphs")
    n = N_MARKERS
    raw = markers.reshape(b, big_l * n, 2)
    if remove_common_motion:
        markers = without_common_motion(markers, rest)
    pos = markers.reshape(b, big_l * n, 2)
    static = np.broadcast_to(static_marker_features(rest), (b, big_l, n, 3))
    ids = np.broadcast_to(np.eye(n, dtype=np.float32), (b, big_l, n, n))
    times = np.broadcast_to(np.eye(big_l, dtype=np.float32)[:, None, :], (b, big_l, n, big_l))
    x = np.concatenate([markers, static[..., :1], static[..., 1:], ids, times], axis=-1)
    x = x.reshape(b, big_l * n, -1)

    sp = topo.edge_index[:, topo.block("spatial")]
    spatial = _edge_geometry(pos[:, sp[0]], pos[:, sp[1]])

    tp = topo.edge_index[:, topo.block("temporal")]
    geo = _edge_geometry(pos[:, tp[0]], pos[:, tp[1]])
    half = tp.shape[1] // 2  # forward block first, then backward
    direction = np.repeat(np.array([FORWARD, BACKWARD], np.float32), half, axis=0)
    temporal = np.concatenate([geo, np.broadcast_to(direction, (b, 2 * half, 2))], axis=-1)

    n_gt = topo.counts["global_temporal"]
    gt = np.repeat(np.array([FORWARD, BACKWARD], np.float32), n_gt // 2, axis=0)
    global_temporal = np.broadcast_to(gt, (b, n_gt, 2))
    return ClipFeatures(x.astype(np.float32), spatial.astype(np.float32), temporal.astype(np.float32),
                        np.ascontiguousarray(global_temporal), raw.astype(np.float32))
