"""Cross-check of the Silicone labels against the prediction viewer's ground-truth panel (SPEC §13.5).

`predictions_sim_to_silicone.mp4` holds 120 states (10 trials x 12 central frames). Its Ground Truth
panel draws the reference's tracked markers of the central frame, under a similarity of ~0.409 panel
px per original px, magenta for label 1 and cyan for label 0. We detect those dots, register our
markers of the same annotation state onto them (similarity + Hungarian) and compare labels marker by
marker.
"""

from __future__ import annotations

import os

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from palpation.markers.order import apply_similarity, fit_similarity
from palpation.paths import VIDEOS
from palpation.realdata.silicone import N_FRAMES
from palpation.realdata.video import PREDICTION_OFFSET, read_states

PREDICTION_VIDEO = VIDEOS / "predictions_sim_to_silicone.mp4"
GT_PANEL = (48, 452, 22, 426)  # y0, y1, x0, x1 of the Ground Truth panel in the 1280x960 viewer
PANEL_PX_PER_ORIG_PX = 0.409
CENTRAL_PER_TRIAL = 12  # windows of L = 5 frames: central frames 2..13 (0-based) of each video
N_CHECK_STATES = 120


def annotation_state(panel_state: int) -> int:
    """Viewer state s -> annotation state 16(s//12) + s%12 + 2 (trial s//12 + 1 = video)."""
    if not 0 <= panel_state < N_CHECK_STATES:
        raise ValueError(f"viewer state must be 0..{N_CHECK_STATES - 1}, got {panel_state}")
    return N_FRAMES * (panel_state // CENTRAL_PER_TRIAL) + panel_state % CENTRAL_PER_TRIAL + 2


def panel_dots(frame_bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth dots of one viewer frame: centres (n, 2) panel px and labels (n,) int8."""
    y0, y1, x0, x1 = GT_PANEL
    crop = np.asarray(frame_bgr[y0:y1, x0:x1], dtype=np.int16)
    b, g, r = crop[..., 0], crop[..., 1], crop[..., 2]
    masks = {1: (r > 150) & (b > 150) & (g < 100),  # magenta = 1
             0: (g > 150) & (b > 150) & (r < 100)}  # cyan = 0
    centres, labels = [], []
    for label, mask in masks.items():
        n, _, stats, cen = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
        keep = stats[1:, cv2.CC_STAT_AREA] >= 10  # a dot is ~36 px2; drop anti-aliasing specks
        centres.append(cen[1:][keep])
        labels.append(np.full(int(keep.sum()), label, np.int8))
    return np.vstack(centres).reshape(-1, 2), np.concatenate(labels)


def register_to_panel(markers_px: np.ndarray, dots_px: np.ndarray, iterations: int = 10
                      ) -> tuple[np.ndarray, np.ndarray, float]:
    """Match our (127, 2) markers to panel dots: -> (dot index per marker, -1 if none), similarity
    2x3, mean residual (panel px). Starts at the known panel scale with centroids aligned."""
    markers = np.asarray(markers_px, float)
    dots = np.asarray(dots_px, float)
    if len(dots) < 3:
        raise ValueError(f"ground-truth panel shows {len(dots)} dots, need >= 3 to register; check "
                         f"the crop {GT_PANEL} and the colour thresholds")
    s = PANEL_PX_PER_ORIG_PX
    matrix = np.hstack([s * np.eye(2), (dots.mean(0) - s * markers.mean(0))[:, None]])
    for _ in range(iterations):
        cost = ((apply_similarity(matrix, markers)[:, None] - dots[None]) ** 2).sum(-1)
        rows, cols = linear_sum_assignment(cost)
        new = fit_similarity(markers[rows], dots[cols])
        if np.allclose(new, matrix, atol=1e-9):
            break
        matrix = new
    cost = ((apply_similarity(matrix, markers)[:, None] - dots[None]) ** 2).sum(-1)
    rows, cols = linear_sum_assignment(cost)
    index = np.full(len(markers), -1)
    index[rows] = cols
    return index, matrix, float(np.sqrt(cost[rows, cols]).mean())


def check_labels(markers: np.ndarray, labels: np.ndarray, path: str | os.PathLike = PREDICTION_VIDEO,
                 panel_states=range(N_CHECK_STATES), chord_distance: np.ndarray | None = None) -> dict:
    """Per-state agreement of our labels with the panel. `markers` (10, 16, 127, 2) sensor px and
    `labels` (10, 16, 127) as in the Silicone set; with its `chord_distance_px`, each disagreement
    lists our marker's distance to the chord (boundary cases sit near 30 px)."""
    panel_states = list(panel_states)
    frames = read_states(path, hold=5, offset=PREDICTION_OFFSET, states=panel_states)
    if frames.shape[1:3] != (960, 1280):
        raise ValueError(f"{path}: frames are {frames.shape[2]}x{frames.shape[1]}, expected the "
                         "1280x960 prediction viewer (predictions_sim_to_silicone.mp4)")
    per_state = []
    for s, frame in zip(panel_states, frames):
        a = annotation_state(s)
        v, f = divmod(a, N_FRAMES)
        dots, dot_labels = panel_dots(frame)
        index, matrix, residual = register_to_panel(markers[v, f], dots)
        matched = index >= 0
        panel = np.full(len(index), -1, np.int8)
        panel[matched] = dot_labels[index[matched]]
        agree = panel[matched] == labels[v, f][matched]
        differ = [{"marker": int(i), "ours": int(labels[v, f, i]), "panel": int(panel[i]),
                   "chord_distance_px": None if chord_distance is None else float(chord_distance[v, f, i])}
                  for i in np.flatnonzero(matched & (panel != labels[v, f]))]
        per_state.append({
            "panel_state": s, "annotation_state": a, "video": v + 1, "frame": f + 1,
            "n_panel_dots": len(dots), "n_matched": int(matched.sum()),
            "agreement": float(agree.mean()), "disagreements": int((~agree).sum()), "differ": differ,
            "panel_positives": int((panel == 1).sum()), "our_positives": int(labels[v, f].sum()),
            "residual_panel_px": residual, "scale_panel_px_per_orig_px": float(np.sqrt(abs(
                np.linalg.det(matrix[:, :2])))),
        })
    agreement = np.array([r["agreement"] for r in per_state])
    return {
        "source": str(path), "n_states": len(per_state),
        "mean_agreement": float(agreement.mean()), "min_agreement": float(agreement.min()),
        "marker_agreement": float(1 - sum(r["disagreements"] for r in per_state)
                                  / sum(r["n_matched"] for r in per_state)),
        "panel_positives": sum(r["panel_positives"] for r in per_state),
        "our_positives": sum(r["our_positives"] for r in per_state),
        "median_residual_panel_px": float(np.median([r["residual_panel_px"] for r in per_state])),
        "per_state": per_state,
    }
