"""Frame-to-frame tracking of the 127 ordered markers through a sequence (SPEC §5.2, real sequences).

Frame 0 is ordered onto the template (pre-aligned Hungarian). Every later frame is matched to the
previous frame's positions by a Hungarian with a dummy slot per marker at cost `max_step_px`²: a
marker whose detection vanished takes the dummy instead of stealing a neighbour's detection (which
would cascade into swaps). Unmatched markers are filled with the previous position plus the mean
displacement of their found lattice neighbours and flagged False in the found mask.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from palpation.markers.lattice import median_spacing_px, neighbours
from palpation.markers.order import warp_template


def match_to_previous(previous: np.ndarray, detections: np.ndarray, max_step_px: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Match detections to last frame's (M, 2) positions: -> (positions (M, 2) NaN gaps, found (M,))."""
    prev = np.asarray(previous, float)
    det = np.asarray(detections, float).reshape(-1, 2)
    det = det[np.all(np.isfinite(det), axis=1)]
    positions = np.full_like(prev, np.nan)
    found = np.zeros(len(prev), dtype=bool)
    if len(det) == 0:
        return positions, found
    cost = ((prev[:, None, :] - det[None, :, :]) ** 2).sum(-1)
    dummy = np.full((len(prev), len(prev)), float(max_step_px) ** 2)
    rows, cols = linear_sum_assignment(np.hstack([cost, dummy]))
    real = (cols < len(det)) & (cost[rows, np.minimum(cols, len(det) - 1)] <= max_step_px ** 2)
    positions[rows[real]] = det[cols[real]]
    found[rows[real]] = True
    return positions, found


def fill_missing(previous: np.ndarray, positions: np.ndarray, found: np.ndarray,
                 nbrs: Sequence[np.ndarray]) -> np.ndarray:
    """Fill unfound markers: previous position + mean displacement of found neighbours.

    A marker with no found neighbour takes the median displacement of all found markers (or stays
    put if none was found).
    """
    out = np.array(positions, dtype=float)
    step = out - previous
    global_step = np.median(step[found], axis=0) if found.any() else np.zeros(2)
    for i in np.flatnonzero(~found):
        ok = nbrs[i][found[nbrs[i]]]
        out[i] = previous[i] + (step[ok].mean(axis=0) if len(ok) else global_step)
    return out


def track_sequence(detections: list[np.ndarray], template: np.ndarray, max_step_px: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Track markers through `detections` (per frame, unordered (N_t, 2) px, extras allowed).

    `template` (M, 2) gives the order and lattice (e.g. `rest_template()`, or it mapped into video
    pixels); frame 0 may be offset, scaled and rolled against it. `max_step_px` gates the motion of
    one marker between consecutive frames (and, at frame 0, the distance to the pre-aligned template).
    Returns positions (T, M, 2) float64, every entry finite, and found (T, M) bool (False = filled).
    """
    if len(detections) == 0:
        raise ValueError("track_sequence got no frames; pass at least one (N, 2) detection array")
    if not max_step_px > 0:
        raise ValueError(f"max_step_px must be > 0, got {max_step_px}")
    tpl = np.asarray(template, float)
    positions = np.empty((len(detections), len(tpl), 2))
    found = np.zeros((len(detections), len(tpl)), dtype=bool)
    for t, det in enumerate(detections):
        det = np.asarray(det, float).reshape(-1, 2)
        if det.shape[0] and det.shape[1] != 2:
            raise ValueError(f"frame {t}: detections must be (N, 2), got {det.shape}")
        if t == 0:
            enough = np.isfinite(det).all(axis=1).sum() >= 12
            previous = warp_template(tpl, det) if enough else tpl
            nbrs = neighbours(previous)
        else:
            previous = positions[t - 1]
        pos, ok = match_to_previous(previous, det, max_step_px)
        positions[t] = fill_missing(previous, pos, ok, nbrs)
        found[t] = ok
    return positions, found


def template_spacing_px(template: np.ndarray) -> float:
    """Median lattice spacing of a template: a convenient scale for `max_step_px`."""
    return median_spacing_px(template)
