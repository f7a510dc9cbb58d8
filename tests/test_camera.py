"""Fisheye camera: project and unproject_to_plane invert each other (SPEC §5.1)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from palpation.camera import DEFAULT_CAMERA, Fisheye

CAM = DEFAULT_CAMERA
radius = st.floats(0.0, CAM.circle_radius_px * (1 - 1e-9), allow_nan=False)
angle = st.floats(-np.pi, np.pi, allow_nan=False)
distance = st.floats(5.0, 50.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(r=radius, phi=angle, d_mm=distance)
def test_project_unproject_is_identity_on_pixels(r, phi, d_mm):
    uv = CAM.centre + r * np.array([np.cos(phi), np.sin(phi)])
    back = CAM.project(CAM.unproject_to_plane(uv, d_mm))
    np.testing.assert_allclose(back, uv, rtol=0, atol=1e-9)


@settings(max_examples=300, deadline=None)
@given(r=radius, phi=angle, d_mm=distance)
def test_unproject_project_is_identity_on_the_plane(r, phi, d_mm):
    # a point of the plane z = D whose ray lies inside the image circle
    rho = d_mm * np.tan(r / CAM.f_px)
    p = np.array([rho * np.cos(phi), rho * np.sin(phi), d_mm])
    back = CAM.unproject_to_plane(CAM.project(p), d_mm)
    np.testing.assert_allclose(back, p, rtol=0, atol=1e-9)


def test_known_values():
    np.testing.assert_allclose(CAM.project(np.array([0.0, 0.0, 19.0])), [1040.0, 584.0])
    # 90 deg off-axis lands at f * pi / 2 from the centre (equidistant model)
    np.testing.assert_allclose(CAM.project(np.array([1.0, 0.0, 0.0])), [1040.0 + 380.0 * np.pi / 2, 584.0])
    p = CAM.unproject_to_plane(np.array([[1040.0 + 380.0, 584.0]]), 10.0)
    np.testing.assert_allclose(p, [[10.0 * np.tan(1.0), 0.0, 10.0]])


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="distance"):
        CAM.unproject_to_plane(np.array([1040.0, 584.0]), 0.0)
    with pytest.raises(ValueError, match="lens centre"):
        CAM.project(np.zeros(3))
    with pytest.raises(ValueError, match="90 deg"):
        Fisheye().unproject_to_plane(np.array([1040.0 + 380.0 * 1.6, 584.0]), 10.0)
