"""The real Meat set (SPEC §1.1 C, §13.5) rebuilt from the Ground Truth panel of the A-to-C viewer.

The viewer is the only Meat data: 219 states, each the central frame of an L = 5 clip, so state k
of a trial (0-based) is trial frame k + 2 and a trial yields its frames 2..T-3 (T = 26, or 25).
Panel dots are the tracked markers in panel pixels, drawn at integer positions (1 panel px is
~2.4 sensor px, so positions carry ~0.7 px RMS of rounding). We order them onto the 127-marker rest
template (Hungarian, squared-Euclidean cost, SPEC §5.2) and map them to sensor pixels with a
similarity. The viewer does not mirror: the fitted roll is ~0.05 deg, and the straw crosses the
image towards +x as the slide along world -y predicts (SPEC §12, x_cam = y_w - pose_y).

Similarity scope. The viewer draws every state of a video through one fixed transform: the two
Silicone viewers show the same markers with a relative similarity that is constant over all 120
states (scale 0.9966 +- 0.0004, roll < 0.04 deg), and Meat panel extents are normalised neither
per state nor per trial. A per-state fit would erase the rigid motion of the markers between
frames (which the temporal edges see); a per-trial fit would erase the mean press expansion that
differs between trials (fitted scales spread 2.5 %). So the default is one similarity per video;
"trial" and "state" remain options. Either way the fit absorbs the video's mean deformation.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from palpation.markers.lattice import median_spacing_px
from palpation.markers.order import apply_similarity, fit_similarity
from palpation.realdata.panels import PanelDots, state_frame

N_STATES = 219
N_MARKERS = 127
FIRST_CENTRAL_FRAME = 2  # L = 5: the first window is centred on trial frame 2 (0-based)
SCOPES = ("video", "trial", "state")
MAX_PANEL_MATCH_PX = 4.0  # Ground Truth vs Hard Prediction dots: same positions, ~1 px jitter


@dataclass(frozen=True)
class MeatTrial:
    trial_id: int
    first_state: int
    n_states: int
    description: str
    split: str  # SPEC §10 Meat splits (C-to-B training)

    @property
    def states(self) -> range:
        return range(self.first_state, self.first_state + self.n_states)


TRIALS = (
    MeatTrial(1, 0, 22, "1 metal straw beneath 1 steak", "train"),
    MeatTrial(2, 22, 21, "1 metal straw beneath 2 steaks", "train"),
    MeatTrial(3, 43, 22, "1 metal straw beneath 3 steaks", "train"),
    MeatTrial(4, 65, 22, "1 metal straw beneath 4 steaks", "train"),
    MeatTrial(5, 87, 22, "1 metal straw beneath 6 steaks", "val"),
    MeatTrial(6, 109, 22, "1 metal straw on top", "train"),
    MeatTrial(7, 131, 22, "1 silicone straw beneath 2 steaks", "val"),
    MeatTrial(8, 153, 22, "2 metal straws beneath 2 steaks", "train"),
    MeatTrial(9, 175, 22, "3 metal straws beneath 2 steaks", "val"),
    MeatTrial(10, 197, 22, "no straw", "train"),
)


def state_to_trial(state: int) -> tuple[MeatTrial, int]:
    """Viewer state -> (trial, 0-based trial frame it shows)."""
    for trial in TRIALS:
        if state in trial.states:
            return trial, state - trial.first_state + FIRST_CENTRAL_FRAME
    raise ValueError(f"Meat viewer state {state} out of range 0..{N_STATES - 1}")


def scope_groups(scope: str) -> list[np.ndarray]:
    """State indices that share one similarity under `scope`."""
    if scope == "video":
        return [np.arange(N_STATES)]
    if scope == "trial":
        return [np.asarray(t.states) for t in TRIALS]
    if scope == "state":
        return [np.array([s]) for s in range(N_STATES)]
    raise ValueError(f"unknown similarity scope {scope!r}; choose one of {SCOPES}")


def similarity_params(matrix: np.ndarray) -> dict[str, float]:
    """Scale, roll (deg) and translation of a 2x3 similarity, for logs and metadata."""
    return {"scale": float(np.sqrt(abs(np.linalg.det(matrix[:, :2])))),
            "rotation_deg": float(np.degrees(np.arctan2(matrix[1, 0], matrix[0, 0]))),
            "tx": float(matrix[0, 2]), "ty": float(matrix[1, 2])}


def hungarian_order(reference: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Index array `idx` with points[idx] matched to `reference` row by row (squared distance)."""
    cost = ((reference[:, None, :] - points[None, :, :]) ** 2).sum(-1)
    rows, cols = linear_sum_assignment(cost)
    return cols[np.argsort(rows)]


def moment_guess(points: np.ndarray, template: np.ndarray) -> np.ndarray:
    """Similarity matching centroid and RMS radius, no roll (the viewer does not rotate)."""
    p0, t0 = points.mean(0), template.mean(0)
    scale = np.sqrt(((template - t0) ** 2).sum(1).mean() / ((points - p0) ** 2).sum(1).mean())
    return np.hstack([scale * np.eye(2), (t0 - scale * p0)[:, None]])


def fit_state(points: np.ndarray, template: np.ndarray, max_iter: int = 20) -> np.ndarray:
    """Similarity of one state's dots onto the template: alternate Hungarian order and fit."""
    matrix = moment_guess(points, template)
    for _ in range(max_iter):
        idx = hungarian_order(template, apply_similarity(matrix, points))
        new = fit_similarity(points[idx], template)
        if np.allclose(new, matrix, rtol=0, atol=1e-9):
            break
        matrix = new
    return matrix


def align_states(panel_xy: np.ndarray, template: np.ndarray,
                 groups: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Order (S, 127, 2) panel dots onto `template`; one panel->sensor similarity per group.

    Returns (idx (S, 127): panel_xy[s, idx[s]] is in template order, matrices (S, 2, 3)). The order
    comes from each state's own fit, which absorbs the state's mean expansion and shift, so the
    Hungarian only sees the non-rigid part. We do not chain frame to frame (SPEC §5.2): the source
    has a few tracking slips (a hole next to a doubled dot, trials 6 and 7) that chaining would carry
    to the end of the trial, while the panel shows them healed a few states later.
    """
    idx = np.empty(panel_xy.shape[:2], dtype=int)
    for s, points in enumerate(panel_xy):
        idx[s] = hungarian_order(template, apply_similarity(fit_state(points, template), points))
    matrices = np.empty((len(panel_xy), 2, 3))
    for group in groups:
        src = np.concatenate([panel_xy[s][idx[s]] for s in group])
        matrices[group] = fit_similarity(src, np.tile(template, (len(group), 1)))
    return idx, matrices


def match_panels(reference_xy: np.ndarray, other: PanelDots, state: int, source: str) -> np.ndarray:
    """Labels of `other` panel's dots at the `reference_xy` dots: the viewer draws every panel with
    the same layout, so the dots coincide in panel coordinates up to ~1 px of compression jitter."""
    cost = np.linalg.norm(reference_xy[:, None, :] - other.xy[None, :, :], axis=-1)
    rows, cols = linear_sum_assignment(cost)
    worst = cost[rows, cols].max()
    if worst > MAX_PANEL_MATCH_PX:
        raise ValueError(f"{source}: state {state}: a dot of the second panel is {worst:.1f} panel px "
                         f"from its Ground Truth dot (> {MAX_PANEL_MATCH_PX}); check the panel crops")
    return other.labels[cols[np.argsort(rows)]]


def require_full_panels(dots: list[PanelDots], panel: str, source: str | os.PathLike) -> None:
    """Every state must show 127 dots and the video must hold 219 states."""
    if len(dots) != N_STATES:
        raise ValueError(f"{source}: {len(dots)} states read, the Meat viewer has {N_STATES}; is this "
                         f"predictions_sim_to_meat.mp4?")
    for state, d in enumerate(dots):
        if len(d.xy) != N_MARKERS:
            raise ValueError(f"{source}: state {state} ({panel} panel, frame {state_frame(state)}) shows "
                             f"{len(d.xy)} dots, expected {N_MARKERS}; check the panel crop and the "
                             f"colour thresholds")


def build_meat(truth: list[PanelDots], hard: list[PanelDots], template: np.ndarray,
               scope: str = "video", source: str = "predictions_sim_to_meat.mp4") -> dict[str, np.ndarray]:
    """Flat arrays over the 219 states (state order); `trial_offsets` cuts them into trials."""
    require_full_panels(truth, "ground_truth", source)
    require_full_panels(hard, "hard_prediction", source)
    template = np.asarray(template, dtype=np.float64)
    panel_xy = np.stack([d.xy for d in truth])
    idx, matrices = align_states(panel_xy, template, scope_groups(scope))
    ordered = np.take_along_axis(panel_xy, idx[..., None], axis=1)
    markers = np.stack([apply_similarity(m, p) for m, p in zip(matrices, ordered)])
    residual = np.sqrt(((markers - template) ** 2).sum(-1).mean(-1))
    # Real deformation stays well under a quarter spacing in RMS; more means a wrong template or flip.
    if np.median(residual) > 0.25 * median_spacing_px(template):
        raise ValueError(f"{source}: median fit residual {np.median(residual):.1f} px exceeds a quarter "
                         f"marker spacing; the panel does not match the template (mirrored? wrong crop?)")
    labels = np.stack([d.labels[i] for d, i in zip(truth, idx)])
    ref_hard = np.stack([match_panels(p, h, s, source) for s, (p, h) in enumerate(zip(ordered, hard))])
    trial_of = [state_to_trial(s) for s in range(N_STATES)]
    return {
        "markers": markers.astype(np.float32),
        "labels": labels.astype(np.int32),
        "ref_hard_pred": ref_hard.astype(np.int32),
        "trial": np.array([t.trial_id for t, _ in trial_of], dtype=np.int32),
        "frame": np.array([f for _, f in trial_of], dtype=np.int32),
        "state": np.arange(N_STATES, dtype=np.int32),
        "trial_offsets": np.array([t.first_state for t in TRIALS] + [N_STATES], dtype=np.int64),
        "panel_xy": ordered.astype(np.float32),
        "panel_to_sensor": matrices,
        "fit_residual_px": residual.astype(np.float32),
        "template": template,
    }


def trial_sequences(data: dict[str, np.ndarray]) -> list[dict[str, np.ndarray]]:
    """Cut the flat arrays into per-trial sequences: markers (T, 127, 2), labels (T, 127), ..."""
    off = data["trial_offsets"]
    keys = ("markers", "labels", "ref_hard_pred", "frame", "state")
    return [{k: data[k][a:b] for k in keys} | {"trial": TRIALS[i]}
            for i, (a, b) in enumerate(zip(off[:-1], off[1:]))]


def metadata(data: dict[str, np.ndarray], scope: str, source: str) -> dict:
    """JSON-able description of the set: trials, splits, counts and fit residuals."""
    groups = scope_groups(scope)
    res = data["fit_residual_px"]
    half_spacing = 0.5 * median_spacing_px(data["template"])
    trials, jumps = [], []
    for seq in trial_sequences(data):
        t = seq["trial"]
        r = res[list(t.states)]
        step = np.linalg.norm(np.diff(seq["markers"], axis=0), axis=-1)
        # Steps over half a spacing are tracking slips in the source data (a hole next to a doubled
        # dot in the panel), not reading errors; listed so users can mask them.
        jumps += [int(seq["state"][k + 1]) for k in np.flatnonzero(step.max(1) > half_spacing)]
        trials.append({"trial_id": t.trial_id, "description": t.description, "split": t.split,
                       "states": [t.first_state, t.first_state + t.n_states - 1],
                       "frames": [int(seq["frame"][0]), int(seq["frame"][-1])],
                       "n_frames": t.n_states, "positives": int(seq["labels"].sum()),
                       "fit_residual_px_median": float(np.median(r)), "fit_residual_px_max": float(r.max()),
                       "max_step_px": float(step.max())})
    return {
        "source": source, "similarity_scope": scope,
        "similarities": [similarity_params(data["panel_to_sensor"][g[0]]) for g in groups],
        "n_states": N_STATES, "n_markers": N_MARKERS,
        "positives": int(data["labels"].sum()), "nodes": int(data["labels"].size),
        "states_without_positives": int((data["labels"].sum(1) == 0).sum()),
        "max_positives_per_state": int(data["labels"].sum(1).max()),
        "ref_hard_positives": int(data["ref_hard_pred"].sum()),
        "ref_hard_accuracy": float((data["ref_hard_pred"] == data["labels"]).mean()),
        "states_with_tracking_jumps": jumps,
        "fit_residual_px": {"median": float(np.median(res)), "max": float(res.max())},
        "splits": {s: [t.trial_id for t in TRIALS if t.split == s] for s in ("train", "val")},
        "trials": trials,
    }
