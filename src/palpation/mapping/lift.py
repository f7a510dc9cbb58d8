"""2D -> 3D -> 2D: marker pixels onto the sensor-tip plane, into the world, onto the map grid (SPEC §12).

A marker pixel is unprojected through the fisheye onto the plane z = D in the camera frame E (D = 16 mm
for Sim and Silicone: 19 mm lens-to-tip minus the 3 mm press; 19 mm for Meat, undeformed sensor), moved
into the world with the sensor pose of its frame and dropped on a 1 mm/px grid. A pixel's score is the
highest probability that landed on it (-1 where nothing landed); video truth marks pixels hit by a
label-1 sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from palpation.camera import DEFAULT_CAMERA, LENS_TO_TIP_MM, Fisheye
from palpation.mapping.grid import Grid

PLANE_MM = {"sim": 16.0, "silicone": 16.0, "meat": 19.0}
UNVISITED = -1.0


def lift_to_camera(pixels: np.ndarray, plane_mm: float, camera: Fisheye = DEFAULT_CAMERA) -> np.ndarray:
    """(..., 2) sensor pixels -> (..., 3) points on the plane z = plane_mm in the camera frame, mm."""
    return camera.unproject_to_plane(pixels, plane_mm)


def silicone_to_world(p_cam: np.ndarray, robot_xy: np.ndarray) -> np.ndarray:
    """x_w = x_cam + x_r, y_w = -y_cam + y_r; robot_xy (..., 2) broadcasts over the markers."""
    r = np.asarray(robot_xy, np.float64)[..., None, :]
    return np.stack([p_cam[..., 0] + r[..., 0], -p_cam[..., 1] + r[..., 1]], axis=-1)


def meat_to_world(p_cam: np.ndarray, pose_xy: np.ndarray) -> np.ndarray:
    """x_w = pose_x + y_cam, y_w = pose_y + x_cam (the label rule's cam = (rel_y, rel_x, -rel_z))."""
    r = np.asarray(pose_xy, np.float64)[..., None, :]
    return np.stack([r[..., 0] + p_cam[..., 1], r[..., 1] + p_cam[..., 0]], axis=-1)


def sim_to_world(p_cam: np.ndarray, T_BA_m: np.ndarray, lens_to_tip_mm: float = LENS_TO_TIP_MM) -> np.ndarray:
    """p_A = T_BA (p_E - (0, 0, 19 mm)); T_BA (..., 4, 4) in metres; returns world (x, y) in mm."""
    T = np.asarray(T_BA_m, np.float64)
    p_B = (p_cam - np.array([0.0, 0.0, lens_to_tip_mm])) / 1000.0  # mm -> m, body frame
    p_A = np.einsum("...ij,...mj->...mi", T[..., :3, :3], p_B) + T[..., None, :3, 3]
    return p_A[..., :2] * 1000.0


def to_world(dataset: str, pixels: np.ndarray, poses: np.ndarray, camera: Fisheye = DEFAULT_CAMERA) -> np.ndarray:
    """Samples' marker pixels (n, 127, 2) with one pose per sample -> world xy (n, 127, 2) mm.

    poses: Silicone robot (x, y) mm (n, 2); Meat pose (x, y) mm (n, 2); Sim T_BA (n, 4, 4) metres.
    """
    if dataset not in PLANE_MM:
        raise ValueError(f"unknown dataset {dataset!r}: use one of {sorted(PLANE_MM)}")
    pixels, poses = np.asarray(pixels, np.float64), np.asarray(poses, np.float64)
    if len(pixels) != len(poses):
        raise ValueError(f"{dataset}: {len(pixels)} prediction samples but {len(poses)} poses; each central "
                         f"frame needs its own pose (check clip_len and the pose source)")
    p_cam = lift_to_camera(pixels, PLANE_MM[dataset], camera)
    if dataset == "silicone":
        return silicone_to_world(p_cam, poses)
    if dataset == "meat":
        return meat_to_world(p_cam, poses)
    return sim_to_world(p_cam, poses)


@dataclass
class MapStack:
    """M maps on one grid: score (M, H, W) float32 (-1 unvisited), visited and video truth (M, H, W) bool."""

    grid: Grid
    score: np.ndarray
    visited: np.ndarray
    truth: np.ndarray
    names: list = field(default_factory=list)
    dropped: int = 0  # samples that fell outside a fixed grid

    def __post_init__(self):
        if not (self.score.shape == self.visited.shape == self.truth.shape) or self.score.ndim != 3:
            raise ValueError(f"map layers must share one (M, H, W) shape, got {self.score.shape}, "
                             f"{self.visited.shape}, {self.truth.shape}")

    def __len__(self) -> int:
        return len(self.score)


def rasterise(grid: Grid, world_xy: np.ndarray, probs: np.ndarray, labels: np.ndarray, map_id: np.ndarray,
              n_maps: int, names: list | None = None) -> MapStack:
    """Drop samples on the grid: per pixel the max probability (floor index), visited, and video truth.

    world_xy (n, 127, 2) mm, probs/labels (n, 127), map_id (n,) in [0, n_maps).
    """
    world_xy = np.asarray(world_xy, np.float64)
    probs = np.asarray(probs, np.float64).reshape(world_xy.shape[:-1])
    labels = np.asarray(labels).reshape(world_xy.shape[:-1])
    m = np.broadcast_to(np.asarray(map_id, np.int64)[:, None], labels.shape)
    r, c, inside = grid.indices(world_xy)
    ok = inside & np.isfinite(world_xy).all(-1)
    h, w = grid.shape
    flat = (m[ok] * h + r[ok]) * w + c[ok]
    score = np.full(n_maps * h * w, -np.inf)
    np.maximum.at(score, flat, probs[ok])
    visited = np.isfinite(score)
    score[~visited] = UNVISITED
    truth = np.zeros(n_maps * h * w, bool)
    truth[flat[labels[ok] == 1]] = True
    shape = (n_maps, h, w)
    return MapStack(grid, score.reshape(shape).astype(np.float32), visited.reshape(shape), truth.reshape(shape),
                    list(names) if names is not None else [str(i) for i in range(n_maps)], int((~ok).sum()))
