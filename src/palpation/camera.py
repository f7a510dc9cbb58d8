"""Equidistant fisheye camera of the ViTacTip (SPEC §5.1) and the annotation-video pixel mapping.

Camera frame E: origin at the lens, +z along the optical axis towards the dome tip. A point at
angle theta from the axis lands at radius f*theta from the principal point (no distortion terms),
which is `cv2.fisheye.projectPoints` with D = 0. The intrinsics are the reference's hand-set values
(f equals the image-circle radius), a modelling choice the residual loop may revisit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

IMAGE_SIZE_PX = (1920, 1080)  # width, height
PITCH_PX = 55.0  # real marker pitch: 55 px = 2 mm
MM_PER_PX = 2.0 / 55.0
LENS_TO_TIP_MM = 19.0  # camera E = body B shifted by 19 mm along z

# Annotation video (1280x760) shows the sensor image scaled by 0.6443 and offset by (21, 2).
VIDEO_SCALE = 0.6443
VIDEO_OFFSET_PX = (21.0, 2.0)


@dataclass(frozen=True)
class Fisheye:
    """Equidistant fisheye intrinsics in pixels; `rotation_deg` rotates the image about the centre."""

    f_px: float = 380.0
    cx_px: float = 1040.0
    cy_px: float = 584.0
    circle_radius_px: float = 380.0

    @property
    def centre(self) -> np.ndarray:
        return np.array([self.cx_px, self.cy_px])

    def project(self, points_E: np.ndarray) -> np.ndarray:
        """(..., 3) points in the camera frame -> (..., 2) pixels (u right, v down)."""
        p = np.asarray(points_E, dtype=np.float64)
        norm = np.linalg.norm(p, axis=-1)
        if np.any(norm == 0):
            raise ValueError("cannot project a point at the lens centre (|p| = 0)")
        # atan2 keeps full precision near the axis, where arccos(z/|p|) loses ~1e-8 rad (4e-6 px)
        theta = np.arctan2(np.hypot(p[..., 0], p[..., 1]), p[..., 2])
        phi = np.arctan2(p[..., 1], p[..., 0])
        r = self.f_px * theta
        return np.stack([self.cx_px + r * np.cos(phi), self.cy_px + r * np.sin(phi)], axis=-1)

    def unproject_to_plane(self, pixels: np.ndarray, distance: float) -> np.ndarray:
        """(..., 2) pixels -> (..., 3) points on the plane z = `distance` in the camera frame.

        Valid for pixels whose ray angle is below 90 deg (radius < f*pi/2); the image circle is well
        inside that.
        """
        if not distance > 0:
            raise ValueError(f"unprojection plane distance must be > 0, got {distance}")
        uv = np.asarray(pixels, dtype=np.float64)
        xn = (uv[..., 0] - self.cx_px) / self.f_px
        yn = (uv[..., 1] - self.cy_px) / self.f_px
        theta = np.hypot(xn, yn)
        if np.any(theta >= np.pi / 2):
            raise ValueError("pixel ray at or beyond 90 deg from the axis cannot meet the plane")
        phi = np.arctan2(yn, xn)
        rho = distance * np.tan(theta)
        return np.stack([rho * np.cos(phi), rho * np.sin(phi), np.full_like(rho, distance)], axis=-1)

    def inside_circle(self, pixels: np.ndarray, radius_px: float | None = None) -> np.ndarray:
        radius = self.circle_radius_px if radius_px is None else radius_px
        return np.linalg.norm(np.asarray(pixels) - self.centre, axis=-1) < radius


DEFAULT_CAMERA = Fisheye()


def video_to_sensor_px(video_xy: np.ndarray) -> np.ndarray:
    """Annotation-video pixels (1280x760 panel) -> original 1920x1080 sensor pixels."""
    xy = np.asarray(video_xy, dtype=np.float64)
    return (xy - np.asarray(VIDEO_OFFSET_PX)) / VIDEO_SCALE


def sensor_to_video_px(sensor_xy: np.ndarray) -> np.ndarray:
    """Original sensor pixels -> annotation-video pixels (inverse of `video_to_sensor_px`)."""
    xy = np.asarray(sensor_xy, dtype=np.float64)
    return xy * VIDEO_SCALE + np.asarray(VIDEO_OFFSET_PX)
