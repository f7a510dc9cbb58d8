"""The 127-marker hexagonal layout and the base-graph order (SPEC §5.2).

Pure geometry, no image I/O: `template.py` re-exports these and adds the rest template measured on
the shipped photo. Kept separate so `detect.py` can prune against an ideal lattice without a cycle.
"""

from __future__ import annotations

import numpy as np

N_RINGS = 6
RING_SIZES = tuple([1] + [6 * k for k in range(1, N_RINGS + 1)])  # 1, 6, 12, ..., 36
N_MARKERS = sum(RING_SIZES)  # 127
# ring_index[i] = hexagonal ring of marker i in base-graph order
RING_INDEX = np.repeat(np.arange(N_RINGS + 1), RING_SIZES)


def ring_index(n_markers: int = N_MARKERS) -> np.ndarray:
    """(n,) ring number of each marker in base-graph order (0 = centre, 6 = outer ring)."""
    if n_markers != N_MARKERS:
        raise ValueError(f"the hexagonal layout has {N_MARKERS} markers, got n_markers={n_markers}")
    return RING_INDEX.copy()


def ring_slice(ring: int) -> slice:
    """Index range of `ring` in base-graph order."""
    if not 0 <= ring <= N_RINGS:
        raise ValueError(f"ring must be in 0..{N_RINGS}, got {ring}")
    start = sum(RING_SIZES[:ring])
    return slice(start, start + RING_SIZES[ring])


def _bearing_deg(d: np.ndarray) -> np.ndarray:
    """Clockwise angle from image-up, atan2(dx, -dy) in degrees mod 360 (y points down).

    Rounded to 1e-9 deg so an exact lattice direction (e.g. straight up) never flips to 359.999...
    """
    deg = np.degrees(np.arctan2(d[:, 0], -d[:, 1]))
    return np.mod(np.round(deg, 9), 360.0)


def base_graph_order(points: np.ndarray) -> np.ndarray:
    """Permutation `order` such that `points[order]` is in base-graph order (SPEC §5.2).

    Marker 0 is the point nearest the centroid; the rest are sorted by distance to it, ring k takes
    the next 6k, and each ring is sorted by bearing. Ties are broken by coordinates, so the result
    does not depend on the input order.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape != (N_MARKERS, 2):
        raise ValueError(f"base_graph_order needs ({N_MARKERS}, 2) points, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("base_graph_order got non-finite coordinates; fill or drop missing markers first")
    d_centroid = np.linalg.norm(pts - pts.mean(axis=0), axis=1)
    centre = np.lexsort((pts[:, 1], pts[:, 0], d_centroid))[0]
    offset = pts - pts[centre]
    dist = np.linalg.norm(offset, axis=1)
    dist[centre] = -1.0  # the centre always comes first
    by_dist = np.lexsort((pts[:, 1], pts[:, 0], np.round(dist, 9)))
    order = [by_dist[:1]]
    start = 1
    for size in RING_SIZES[1:]:
        ring = by_dist[start:start + size]
        bearing = _bearing_deg(offset[ring])
        order.append(ring[np.lexsort((pts[ring, 1], pts[ring, 0], bearing))])
        start += size
    return np.concatenate(order)


def ideal_hex_lattice(pitch_px: float = 1.0, rotation_deg: float = 0.0,
                      centre_px: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """(127, 2) regular hexagon of markers in base-graph order.

    At rotation 0 one lattice direction is image-horizontal, as on the sensor (whose ring-6 corners
    sit at bearings 30 + 60k deg); positive rotation turns the lattice clockwise on screen (y down).
    """
    q, r = np.meshgrid(np.arange(-N_RINGS, N_RINGS + 1), np.arange(-N_RINGS, N_RINGS + 1))
    q, r = q.ravel(), r.ravel()
    inside = np.maximum(np.maximum(np.abs(q), np.abs(r)), np.abs(q + r)) <= N_RINGS
    q, r = q[inside], r[inside]
    xy = np.stack([q + r / 2.0, r * np.sqrt(3.0) / 2.0], axis=1)
    a = np.radians(rotation_deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    xy = xy @ rot.T
    xy = xy[base_graph_order(xy)]
    return pitch_px * xy + np.asarray(centre_px, dtype=np.float64)


def neighbours(points: np.ndarray, max_dist_factor: float = 1.5) -> list[np.ndarray]:
    """Lattice neighbours of each marker: the points within `max_dist_factor` x median spacing."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64)
    tree = cKDTree(pts)
    spacing = float(np.median(tree.query(pts, 2)[0][:, 1]))
    return [np.array(sorted(set(n) - {i}), dtype=int)
            for i, n in enumerate(tree.query_ball_point(pts, max_dist_factor * spacing))]


def median_spacing_px(points: np.ndarray) -> float:
    """Median nearest-neighbour distance (the SPEC's 'spacing'), ignoring NaN rows."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 2:
        raise ValueError(f"need at least 2 finite points to measure spacing, got {len(pts)}")
    return float(np.median(cKDTree(pts).query(pts, 2)[0][:, 1]))
