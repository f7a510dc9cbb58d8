"""Residual modes: each named field lands in its own mode, shares sum to 1, the stretch axis is found."""

import numpy as np
import pytest

from palpation.loop.residual import CENTRE_PX, MODES, decompose, image_direction_deg
from palpation.markers.template import rest_template


@pytest.fixture(scope="module")
def real():
    return rest_template().astype(np.float64)


def rotate(q, deg):
    a = np.radians(deg)
    return q @ np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]).T


@pytest.mark.parametrize("mode, field", [
    ("translation", lambda q: np.tile([3.0, -2.0], (len(q), 1))),
    ("rotation", lambda q: rotate(q, 1.5) - q),
    ("radial", lambda q: 0.04 * q),
])
def test_pure_fields_fall_in_their_mode(real, mode, field):
    dec = decompose(real + field(real - CENTRE_PX), real, "x")
    assert dec.shares[mode] > 0.99
    assert sum(dec.shares.values()) == pytest.approx(1.0, abs=1e-12)
    assert set(dec.shares) == set(MODES)


def test_stretch_axis_and_slide_angle(real):
    q = real - CENTRE_PX
    axis = np.radians(30.0)
    u = np.array([np.cos(axis), np.sin(axis)])
    dec = decompose(real + 0.05 * np.outer(q @ u, u) - 0.025 * q, real, "s", slide_image_deg=-60.0)
    assert dec.shares["stretch_shear"] > 0.95
    assert dec.stretch_axis_deg == pytest.approx(30.0, abs=0.5)
    assert dec.axis_vs_slide_deg == pytest.approx(90.0, abs=0.5)  # 30 vs -60 deg: perpendicular
    assert dec.stretch_pct == pytest.approx(2.5, abs=0.1)


def test_local_field_is_what_remains(real):
    bump = np.zeros_like(real)
    bump[:7] = [[4.0, 1.0], [-4.0, 1.0], [1.0, 4.0], [1.0, -4.0], [3.0, 3.0], [-3.0, -3.0], [0.0, 2.0]]
    dec = decompose(real + bump, real, "bump")
    assert dec.shares["local"] > 0.99 and dec.local_central_fraction > 0.99
    with pytest.raises(ValueError, match="not finite"):
        decompose(np.full_like(real, np.nan), real, "nan")


def test_slide_direction_in_the_image():
    # the nominal slide (world -y) through the dome-down sensor yawed by -10.37 deg: image up, 10.37 deg right
    assert image_direction_deg(-90.0) == pytest.approx(-90.0 + 10.37, abs=1e-6)
