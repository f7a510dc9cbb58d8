"""Rotation augmentation and Sim labels (SPEC §7 label rule, §8.3, quirk 14).

One rotation per training clip from {0, 60, ..., 300} deg about the image point (1040, 584), applied
to the markers and the centreline. `reference` mode (quirk 14) leaves node ids unchanged, so the id
one-hots and rest polar features no longer match where a marker now sits. `consistent` mode also
renumbers the nodes by the rotation's lattice permutation, so every node again sits at its own rest site.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

ROTATION_CENTRE_PX = (1040.0, 584.0)
ROTATION_STEP_DEG = 60
N_ROTATIONS = 6
LABEL_RADIUS_PX = 30.0
ROTATION_MODES = ("none", "reference", "consistent", "lattice")  # lattice: palpation.graph.clips.ClipSet.gather


def rotate_points(points: np.ndarray, angle_deg, centre=ROTATION_CENTRE_PX) -> np.ndarray:
    """Rotate (..., 2) px about `centre`; `angle_deg` is a scalar or one angle per leading row."""
    a = np.radians(np.asarray(angle_deg, np.float64))
    c, s = np.cos(a), np.sin(a)
    shape = (-1,) + (1,) * (points.ndim - 2) if np.ndim(a) else ()
    c, s = np.reshape(c, shape), np.reshape(s, shape)
    p = np.asarray(points, np.float64) - centre
    out = np.stack([c * p[..., 0] - s * p[..., 1], s * p[..., 0] + c * p[..., 1]], axis=-1) + centre
    return out.astype(np.float32)


def rotation_permutations(rest: np.ndarray) -> np.ndarray:
    """(6, 127): perm[r][j] = the marker that lands on rest site j after rotating by 60·r deg."""
    rest = np.asarray(rest, np.float64)
    perms = []
    for r in range(N_ROTATIONS):
        moved = rotate_points(rest, ROTATION_STEP_DEG * r).astype(np.float64)
        cost = np.linalg.norm(rest[:, None, :] - moved[None, :, :], axis=-1)  # site j x marker i
        _, marker = linear_sum_assignment(cost)
        perms.append(marker)
    return np.stack(perms)


def sim_labels(markers: np.ndarray, centreline: np.ndarray, contact: np.ndarray,
               radius_px: float = LABEL_RADIUS_PX) -> np.ndarray:
    """Positive iff contact and the marker is < radius_px from the nearest centreline point.

    markers (..., 127, 2), centreline (..., P, 2), contact (...,) -> int8 (..., 127).
    """
    # dx² + dy² per coordinate array is bit-identical to summing the squared (..., 2) differences (a length-2
    # sum is one addition) and ~3x faster: it dominated building a training batch (stacked seeds wait on it)
    m = np.asarray(markers, np.float64)
    c = np.asarray(centreline, np.float64)
    dx = m[..., :, None, 0] - c[..., None, :, 0]
    dy = m[..., :, None, 1] - c[..., None, :, 1]
    d2 = dx * dx
    d2 += dy * dy
    near = d2.min(axis=-1) < radius_px ** 2
    return (near & np.asarray(contact, bool)[..., None]).astype(np.int8)


def draw_rotations(rng: np.random.Generator, n: int, mode: str) -> np.ndarray:
    """Rotation index 0..5 per clip; all zero when augmentation is off."""
    if mode not in ROTATION_MODES:
        raise ValueError(f"unknown rotation mode '{mode}': use one of {ROTATION_MODES}")
    if mode == "none":
        return np.zeros(n, dtype=np.int64)
    return rng.integers(0, N_ROTATIONS, size=n)


# ---- sensor-plausible augmentation of the robust recipe (issue 15); each is off at 0 ----
# Sizes are the detector's measured ones: photo noise < 0.2 px per coordinate (SPEC §13.2); the Silicone
# tracker fills or mask-fits ~0.8 % of marker-frames (results/data/silicone/silicone.json summary).

def jitter_markers(markers: np.ndarray, rng: np.random.Generator, std_px: float) -> np.ndarray:
    """Gaussian detector noise, independent per marker, frame and coordinate."""
    if std_px <= 0:
        return markers
    return (markers + rng.normal(0.0, std_px, markers.shape)).astype(np.float32)


def drop_markers(markers: np.ndarray, rng: np.random.Generator, rate: float) -> np.ndarray:
    """Missed detections: a dropped marker keeps its previous frame's position, as a tracker holds it.

    markers (B, L, 127, 2); frame 0 is never dropped (it has no previous frame). Drops chain, so a
    marker missed twice in a row holds the last detected position."""
    if rate <= 0:
        return markers
    out = np.array(markers, np.float32, copy=True)
    drop = rng.random(out.shape[:3]) < rate
    for t in range(1, out.shape[1]):
        out[:, t][drop[:, t]] = out[:, t - 1][drop[:, t]]
    return out


def draw_displacement_scales(rng: np.random.Generator, n: int, spread: float) -> np.ndarray | None:
    """One displacement-magnitude factor per clip, U(1 - spread, 1 + spread); None when off."""
    if spread <= 0:
        return None
    if spread >= 1:
        raise ValueError(f"displacement_scale must be in [0, 1) (factor U(1-s, 1+s)), got {spread}")
    return rng.uniform(1.0 - spread, 1.0 + spread, size=n)
