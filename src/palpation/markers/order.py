"""Put detections into template order: a robust pre-alignment, then a Hungarian match (SPEC §5.2).

The pre-alignment removes the global offset, scale and roll between a template and a photo (or a
scaled video frame) with a similarity; a smooth cubic warp then takes up the large-scale part of the
deformation and the lens' radial compression (a 20 deg twist_x squeezes one side of the image by
half a spacing). What is left for the squared-Euclidean Hungarian is a few pixels, so it can neither
swap neighbours nor take glare.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from palpation.markers.lattice import median_spacing_px


def apply_similarity(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 2x3 similarity (or affine) matrix to (N, 2) points."""
    pts = np.asarray(points, dtype=np.float64)
    return pts @ matrix[:, :2].T + matrix[:, 2]


def fit_similarity(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares similarity src -> dst (Umeyama, no reflection) as a 2x3 matrix."""
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    mu_s, mu_d = src.mean(0), dst.mean(0)
    s0, d0 = src - mu_s, dst - mu_d
    cov = d0.T @ s0 / len(src)
    u, sig, vt = np.linalg.svd(cov)
    sign = np.sign(np.linalg.det(u @ vt)) or 1.0
    fix = np.diag([1.0, sign])
    rot = u @ fix @ vt
    scale = np.trace(np.diag(sig) @ fix) / s0.var(0).sum()
    return np.hstack([scale * rot, (mu_d - scale * rot @ mu_s)[:, None]])


def _mutual_pairs(moved: np.ndarray, pts: np.ndarray, tree: cKDTree, max_px: float):
    """Template indices and point indices of mutual nearest neighbours closer than `max_px`."""
    d, j = tree.query(moved)
    back = cKDTree(moved).query(pts[j])[1]
    ok = (back == np.arange(len(moved))) & (d < max_px)
    return np.flatnonzero(ok), j[ok]


def _coarse_to_fine(tpl: np.ndarray, tpl_spacing: float):
    """Template index sets growing from the centre: deformation adds up towards the rim, so the
    inner rings pin the fit before the outer ones (which carry the most leverage) join in."""
    r = np.linalg.norm(tpl - np.median(tpl, 0), axis=1) / tpl_spacing
    return [np.flatnonzero(r <= radius) for radius in (2.5, 3.5, 4.5, 5.5, np.inf)]


def _similarity_icp(tpl, pts, tree, matrix, stages, gate_px, iterations):
    for use in stages:
        for _ in range(iterations):
            i, j = _mutual_pairs(apply_similarity(matrix, tpl[use]), pts, tree, gate_px)
            if len(i) < 3:
                break
            new = fit_similarity(tpl[use[i]], pts[j])
            converged = np.allclose(new, matrix, atol=1e-9)
            matrix = new
            if converged:
                break
    return matrix


def _poly_features(xy: np.ndarray, degree: int = 3) -> np.ndarray:
    """Monomials up to `degree` (1, 2 or 3): the cubic terms carry the fisheye's radial compression."""
    u, v = xy[:, 0], xy[:, 1]
    terms = [np.ones_like(u), u, v, u * u, u * v, v * v, u ** 3, u * u * v, u * v * v, v ** 3]
    return np.stack(terms[:{1: 3, 2: 6, 3: 10}[degree]], axis=1)


def _polynomial_icp(tpl, pts, tree, warped, stages, gate_px, iterations, tpl_spacing, degree=3):
    # O(1) coordinates keep the least squares well posed
    features = _poly_features((tpl - np.median(tpl, 0)) / (10 * tpl_spacing), degree)
    for use in (stages if degree < 3 else stages[1:]):
        for _ in range(iterations):
            i, j = _mutual_pairs(warped[use], pts, tree, gate_px)
            if len(i) < 2 * features.shape[1]:
                break
            new = features @ np.linalg.lstsq(features[use[i]], pts[j], rcond=None)[0]
            converged = np.allclose(new, warped, atol=1e-6)
            warped = new
            if converged:
                break
    return warped


def _starts(tpl: np.ndarray, pts: np.ndarray, rotation_deg: float) -> list[np.ndarray]:
    """Initial similarities: medians and spacings matched, then shifted by each of the 6 lattice
    steps and half-steps. A lattice fits itself one spacing off almost as well, and glare on one side
    can move the median of the detections by more than half a spacing, so every phase is tried."""
    a = np.radians(rotation_deg)
    rot = (median_spacing_px(pts) / median_spacing_px(tpl)
           * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]))
    centre = np.median(tpl, 0)
    start = np.hstack([rot, (np.median(pts, 0) - rot @ centre)[:, None]])
    tree_tpl = cKDTree(tpl)
    c = tree_tpl.query(centre)[1]
    steps = (tpl[tree_tpl.query(tpl[c], 7)[1][1:]] - tpl[c]) @ rot.T
    shifts = np.vstack([np.zeros((1, 2)), 0.5 * steps, steps])
    return [start + np.hstack([np.zeros((2, 2)), shift[:, None]]) for shift in shifts]


def warp_template(template: np.ndarray, points: np.ndarray, polynomial: bool = True,
                  rotation_deg: float = 0.0, iterations: int = 20, gate: float = 0.4,
                  max_unmatched: int = 3) -> np.ndarray:
    """Template positions (M, 2) predicted in the frame of the unordered `points`.

    From each start (`_starts`), a coarse-to-fine trimmed ICP fits a similarity and then, if
    `polynomial`, a third-order polynomial map, on mutual nearest neighbours within `gate` x spacing.
    Outliers (rim glare, missing markers) have no mutual partner and do not pull the fit. The start
    whose result leaves the lowest truncated residual wins. If more than `max_unmatched` template
    markers are left without a detection within the gate, degree-stepped fits are tried as well.
    """
    tpl = np.asarray(template, float)
    pts = np.asarray(points, float)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 3:
        raise ValueError(f"template pre-alignment needs at least 3 detections, got {len(pts)}")
    tpl_spacing = median_spacing_px(tpl)
    gate_px = gate * median_spacing_px(pts)
    stages = _coarse_to_fine(tpl, tpl_spacing)
    tree = cKDTree(pts)
    cost = lambda warped: np.mean(np.minimum(tree.query(warped)[0], gate_px) ** 2)  # noqa: E731
    fits = []
    for start in _starts(tpl, pts, rotation_deg):
        warped = apply_similarity(_similarity_icp(tpl, pts, tree, start, stages, gate_px, iterations), tpl)
        # many starts converge to the same fit: refine each distinct one only once
        if all(np.abs(warped - f).max() > 0.1 * gate_px for f in fits):
            fits.append(warped)
    if not (polynomial and len(pts) >= 20):
        return min(fits, key=cost)
    similar = fits
    fits = [_polynomial_icp(tpl, pts, tree, w, stages, gate_px, iterations, tpl_spacing) for w in similar]
    best = min(fits, key=cost)
    if np.sum(tree.query(best)[0] > gate_px) <= max_unmatched:
        return best
    # A cubic fitted straight onto a similarity can settle one lattice row off when a shear or tilt
    # (camera off-axis) adds to a strong deformation, dropping a whole outer edge. Raising the degree
    # step by step (affine, quadratic, cubic), each over the growing stages, follows the deformation
    # out from the centre; the lowest truncated residual of all fits still decides.
    for w in similar:
        for degree in (1, 2, 3):
            w = _polynomial_icp(tpl, pts, tree, w, stages, gate_px, iterations, tpl_spacing, degree)
        fits.append(w)
    return min(fits, key=cost)


def similarity_prealign(template: np.ndarray, points: np.ndarray, rotation_deg: float = 0.0,
                        iterations: int = 20, gate: float = 0.4) -> np.ndarray:
    """2x3 similarity mapping `template` onto the unordered `points` (robust to extras and misses)."""
    warped = warp_template(template, points, False, rotation_deg, iterations, gate)
    return fit_similarity(np.asarray(template, float), warped)


def order_to_template(points: np.ndarray, template: np.ndarray, prealign: bool = True,
                      max_dist_px: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian-order `points` onto `template`: -> (ordered (M, 2) with NaN gaps, found (M,) bool).

    Cost is the squared distance between each point and the pre-aligned template position
    (`warp_template`; `prealign=False` uses the template as is). Matches farther than `max_dist_px`
    are rejected; extra points are left out.
    """
    tpl = np.asarray(template, float)
    pts = np.asarray(points, float)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    ordered = np.full_like(tpl, np.nan)
    found = np.zeros(len(tpl), dtype=bool)
    if len(pts) == 0:
        return ordered, found
    target = warp_template(tpl, pts) if prealign and len(pts) >= 3 else tpl
    cost = ((target[:, None, :] - pts[None, :, :]) ** 2).sum(-1)
    rows, cols = linear_sum_assignment(cost)
    if max_dist_px is not None:
        keep = cost[rows, cols] <= max_dist_px ** 2
        rows, cols = rows[keep], cols[keep]
    ordered[rows] = pts[cols]
    found[rows] = True
    return ordered, found


def match_with_dummy(points: np.ndarray, target: np.ndarray, dummy_px: float) -> np.ndarray:
    """For each of `points`, the index of its `target` slot, or -1 if it is left to a dummy.

    Each point may take a target slot (cost = distance) or a dummy (cost = `dummy_px`), so a
    point farther than `dummy_px` from every free slot is declared a false positive (SPEC §13.2).
    """
    pts, tgt = np.asarray(points, float), np.asarray(target, float)
    slot = np.full(len(pts), -1)
    if len(pts) == 0:
        return slot
    dist = np.linalg.norm(pts[:, None, :] - tgt[None, :, :], axis=-1)
    rows, cols = linear_sum_assignment(np.hstack([dist, np.full((len(pts), len(pts)), dummy_px)]))
    real = cols < len(tgt)
    slot[rows[real]] = cols[real]
    return slot
