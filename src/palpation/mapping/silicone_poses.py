"""Robot poses of the Silicone sweeps, reconstructed: the available data has none (SPEC §13.6).

What is known (SPEC §13.4, §12): 10 videos = 5 parallel straight paths x 2 directions
(`metadata_<path>_<direction>`); each video is every 16th frame of a recording trimmed to robot
y in [v_y - 80, v_y - 20] mm; the map is the fixed 180 x 100 mm workspace x in [-425, -245],
y in [-54, 46]; path 4 (videos 9-10) crosses no vessel.

Reconstruction (all lengths mm):
* along y, uniform steps from the trim end where the sweep starts: direction 0 runs -y from
  y_c + 30, direction 1 runs +y from y_c - 30, step = 60 / m. `m` is the *mirror sum*: frame k of one
  direction sees the vessels where frame m - k of the other does. We measure it from the clicked dots
  (`estimate_mirror`): 15.8 here, i.e. a ~253-frame recording sampled every 16th frame, step 3.8 mm.
* y_c = v_y - 50 = -4, the workspace centre (v_y = 46, the workspace's upper y bound).
* paths along x at x_c + (2 - p) * spacing: path 0 at +x (the map's left, where the photo shows two
  vessels), path 4 at -x (the vessel-free right of the photo); spacing 35 mm fills the workspace with
  the +-19.5 mm marker footprint.
* direction: dots move to -v in direction-0 videos (robot -y, since y_w = -y_cam + y_r) and the skin
  drags the markers the same way; `direction_evidence` reports both, per video.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from palpation.realdata.silicone import LABEL_CENTRE_PX, SWEEP_NAMES

N_VIDEOS, N_FRAMES = 10, 16
TRIM_MM = (20.0, 80.0)  # SPEC §13.4: y in [v_y - 80, v_y - 20]
MIRROR_RANGE = (14.0, 17.0)  # (N-1)/16 for a 60 mm recording of 225..272 frames: the only plausible sums


@dataclass(frozen=True)
class SweepLayout:
    """Where the five paths lie and how a sweep's frames step along y."""

    path_spacing_mm: float = 35.0
    centre_x_mm: float = -335.0  # workspace centre, x in [-425, -245]
    centre_y_mm: float = -4.0  # v_y - 50 with v_y = 46
    mirror_sum: float = 15.8  # frames k and m - k of the two directions see the same y (estimate_mirror)
    direction0_sign: float = -1.0  # direction 0 moves the robot along -y
    path0_side: float = 1.0  # +1: path 0 at +x (map left); -1: path 0 at -x
    n_paths: int = 5

    @property
    def length_mm(self) -> float:
        return TRIM_MM[1] - TRIM_MM[0]

    @property
    def step_mm(self) -> float:
        return self.length_mm / self.mirror_sum


def sweep_of(video: int) -> tuple[int, int]:
    """0-based video -> (path, direction) from its metadata name `metadata_<path>_<direction>`."""
    if not 0 <= video < len(SWEEP_NAMES):
        raise ValueError(f"Silicone video index {video} out of range 0..{len(SWEEP_NAMES) - 1}")
    _, path, direction = SWEEP_NAMES[video].split("_")
    return int(float(path)), int(float(direction))


def robot_xy(layout: SweepLayout, path: int, direction: int, frames: np.ndarray) -> np.ndarray:
    """Robot (x, y) mm at 0-based video `frames` of one sweep."""
    frames = np.asarray(frames, np.float64)
    x = layout.centre_x_mm + layout.path0_side * ((layout.n_paths - 1) / 2 - path) * layout.path_spacing_mm
    half = layout.length_mm / 2
    sign = layout.direction0_sign if direction == 0 else -layout.direction0_sign
    y = layout.centre_y_mm - sign * half + sign * layout.step_mm * frames  # start at the trim end behind
    return np.stack([np.full_like(y, x), y], axis=-1)


def silicone_poses(layout: SweepLayout = SweepLayout(), n_videos: int = N_VIDEOS,
                   n_frames: int = N_FRAMES) -> np.ndarray:
    """(videos, frames, 2) robot x, y mm of every Silicone frame."""
    return np.stack([robot_xy(layout, *sweep_of(v), np.arange(n_frames)) for v in range(n_videos)])


# ----------------------------------------------------------------------------- evidence from the video
def line_offsets(dots: np.ndarray, counts: np.ndarray, angle_deg: float) -> list[np.ndarray]:
    """Per frame, the signed offset (px) from the image centre of each dot's vessel line (normal to the
    video's fixed line angle): it moves by the robot step each frame, whatever the click's place."""
    th = np.radians(angle_deg)
    normal = np.array([-np.sin(th), np.cos(th)])
    return [(np.asarray(dots[f, :counts[f]], np.float64) - np.asarray(LABEL_CENTRE_PX)) @ normal
            for f in range(len(counts))]


def _crossings(offsets: list[np.ndarray], value: float, step_px=(20.0, 160.0)) -> list[float]:
    """Fractional frames where one vessel of a rising sequence passes `value`."""
    out = []
    for j in range(len(offsets) - 1):
        for d0 in offsets[j]:
            for d1 in offsets[j + 1]:
                if step_px[0] < d1 - d0 < step_px[1] and d0 <= value <= d1:
                    out.append(j + (value - d0) / (d1 - d0))
    return out


def estimate_mirror(dots: np.ndarray, counts: np.ndarray, angles_deg, central_px: float = 200.0) -> dict:
    """Mirror sum m per path from paired videos: for every dot of the -v sweep (within `central_px` of
    the centre, where the fisheye is least distorted), the fractional frame of the +v sweep that sees the
    same line offset; k + j over all pairs, kept in the plausible MIRROR_RANGE (other vessels fall
    outside it), median per path and overall."""
    per_path, pooled = {}, []
    for path in range(N_VIDEOS // 2):
        a, b = 2 * path, 2 * path + 1
        oa, ob = line_offsets(dots[a], counts[a], angles_deg[a]), line_offsets(dots[b], counts[b], angles_deg[b])
        sums = [k + j for k, frame in enumerate(oa) for d in frame if abs(d) < central_px
                for j in _crossings(ob, d)]
        sums = [s for s in sums if MIRROR_RANGE[0] <= s <= MIRROR_RANGE[1]]
        if sums:
            per_path[path] = {"m": float(np.median(sums)), "n": len(sums), "std": float(np.std(sums))}
            pooled += sums
    if not pooled:
        raise ValueError("no paired dot crossings found; cannot estimate the Silicone mirror sum "
                         "(are the dots in sensor px with their counts?)")
    return {"m": float(np.median(pooled)), "n": len(pooled), "std": float(np.std(pooled)), "per_path": per_path}


def direction_evidence(markers: np.ndarray, dots: np.ndarray, counts: np.ndarray, angles_deg) -> list[dict]:
    """Per video: median line-offset step (px/frame; sign = image motion of the world) and the mean
    marker v shift against all videos (skin drag, px). Both negative = robot moving -y."""
    mean_v = markers[..., 1].mean(axis=(1, 2))
    drift = mean_v - mean_v.mean()
    out = []
    for v in range(len(markers)):
        offs = line_offsets(dots[v], counts[v], angles_deg[v])
        steps = [d1 - d0 for k in range(len(offs) - 1) for d0 in offs[k] for d1 in offs[k + 1]
                 if 20 < abs(d1 - d0) < 160 and abs(d0) < 150]
        out.append({"video": v + 1, "sweep": SWEEP_NAMES[v], "dot_step_px": float(np.median(steps)) if steps else None,
                    "marker_drift_px": float(drift[v])})
    return out
