"""Meat sensor poses: straight slides along -y at x = 0 (SPEC §12), timed from the kinematic labels.

The Meat set carries no poses, only trial frame indices of a 429-frame recording decimated by 15 to
26 frames (25 in one trial). The labels, however, are kinematic (SPEC §14): a marker is positive where
the straw strip at y_straw, seen from a camera 24 mm above it with cam = (rel_y, rel_x, -rel_z),
projects. So in a frame where a single straw is fully in view, the positives' mean x_cam (unprojected
at 24 mm) equals y_straw - pose_y. A line through those points gives the slide speed (mm per
decimated frame) and the frame where the sensor is above the straw:

    pose_y(f) = y_straw - speed * (f - f0),  pose_x = 0.

Single-straw trials (1-7, y_straw = -285) are fitted one by one with the pooled speed; trials with
several straws or none take the median f0 of the single-straw trials with the same frame count (the
robot program is the same, only the decimated length differs). Measured here: 4.45 mm/frame, f0 12.2
(26-frame trials) and 11.3 (the 25-frame trial), line residual ~0.5 mm.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from palpation.camera import DEFAULT_CAMERA

LABEL_CAMERA_MM = 24.0  # the label rule's camera height above the straw plane
STRAW_CENTRE_Y_MM = -285.0  # every straw layout of SPEC §14 is centred on y = -285
STRAWS_Y_MM = {0: (), 1: (-285.0,), 2: (-275.0, -295.0), 3: (-285.0, -265.0, -305.0)}  # SPEC §14, by straw count
IN_VIEW_MM = 20.0  # beyond this the strip leaves the image and the positives' mean is biased


def straws_of(description: str) -> int:
    """Number of straws in a trial from its SPEC §13.5 description."""
    d = description.lower()
    if d.startswith("no straw"):
        return 0
    return int(d.split()[0])


def straw_offset_mm(markers: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Per frame: mean x_cam (mm, at 24 mm) of the positive markers; NaN where there are none."""
    out = np.full(len(markers), np.nan)
    for i, (m, lab) in enumerate(zip(markers, labels)):
        pos = np.asarray(lab) == 1
        if pos.any():
            out[i] = DEFAULT_CAMERA.unproject_to_plane(np.asarray(m)[pos], LABEL_CAMERA_MM)[:, 0].mean()
    return out


@dataclass
class MeatPoseFit:
    speed_mm: float  # slide per decimated frame (pose_y decreases)
    f0: dict  # trial index -> frame above the straw centre
    n_frames: dict  # trial index -> trial length in frames (as recorded in the set: frames 2..T-3)
    residual_mm: dict = field(default_factory=dict)  # single-straw trials: RMS of the line fit

    def pose_xy(self, trial: int, frames: np.ndarray) -> np.ndarray:
        frames = np.asarray(frames, np.float64)
        y = STRAW_CENTRE_Y_MM - self.speed_mm * (frames - self.f0[trial])
        return np.stack([np.zeros_like(y), y], axis=-1)

    def to_dict(self) -> dict:
        return {"speed_mm_per_frame": self.speed_mm, "f0": self.f0, "residual_mm": self.residual_mm,
                "rule": "pose_y = -285 - speed * (frame - f0), pose_x = 0"}


def fit_meat_poses(trials: list[dict]) -> MeatPoseFit:
    """trials: dicts with `markers` (T, 127, 2), `labels` (T, 127), `frame` (T,) trial frame indices and
    `description`. Returns the shared speed and one f0 per trial (0-based trial index)."""
    lines, lengths = {}, {}
    for i, t in enumerate(trials):
        lengths[i] = int(np.max(t["frame"])) + 3  # frames 2..T-3 are stored
        if straws_of(t["description"]) != 1:
            continue
        x = straw_offset_mm(t["markers"], t["labels"])
        ok = np.isfinite(x) & (np.abs(x) < IN_VIEW_MM)
        if ok.sum() >= 3:
            lines[i] = (np.asarray(t["frame"], np.float64)[ok], x[ok])
    if not lines:
        raise ValueError("Meat poses: no single-straw trial with >= 3 frames of positives in view; cannot time "
                         "the slides (are the labels all zero?)")
    speed = float(np.median([np.polyfit(f, x, 1)[0] for f, x in lines.values()]))
    if not speed > 0:
        raise ValueError(f"Meat poses: fitted straw motion {speed:.2f} mm/frame is not positive; the trials do "
                         f"not slide along -y as SPEC §12 states (mirrored markers?)")
    f0, residual = {}, {}
    for i, (f, x) in lines.items():
        f0[i] = float(np.median(f - x / speed))
        residual[i] = float(np.sqrt(np.mean((x - speed * (f - f0[i])) ** 2)))
    for i in range(len(trials)):
        if i not in f0:
            same = [f0[j] for j in f0 if lengths[j] == lengths[i]] or list(f0.values())
            f0[i] = float(np.median(same))
    return MeatPoseFit(speed, f0, lengths, residual)


def check_meat_poses(trials: list[dict], fit: MeatPoseFit) -> dict:
    """Per trial with straws: distance (mm) from each label-1 marker, lifted at 19 mm with the fitted
    poses, to the nearest straw axis. The strip is 6-8 mm wide, so ~2 mm means the slides line up."""
    from palpation.mapping.lift import to_world

    out = {}
    for i, t in enumerate(trials):
        straws = np.asarray(STRAWS_Y_MM[straws_of(t["description"])])
        pos = np.asarray(t["labels"]) == 1
        if straws.size == 0 or not pos.any():
            continue
        y = to_world("meat", t["markers"], fit.pose_xy(i, t["frame"]))[..., 1][pos]
        d = np.abs(y[:, None] - straws[None]).min(1)
        out[i] = {"mean_mm": float(d.mean()), "median_mm": float(np.median(d)), "n": int(d.size)}
    return out
