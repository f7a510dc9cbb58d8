"""Reconstructed Silicone sweeps: geometry, the mirror-sum estimate, direction evidence, and (when the
extracted set exists) the check against the phantom photo."""

import dataclasses

import numpy as np
import pytest

from palpation.camera import DEFAULT_CAMERA
from palpation.mapping.silicone_poses import (
    SweepLayout, direction_evidence, estimate_mirror, robot_xy, silicone_poses, sweep_of)
from palpation.paths import REPO_ROOT



def test_sweep_names_give_path_and_direction():
    assert sweep_of(0) == (0, 0) and sweep_of(1) == (0, 1) and sweep_of(9) == (4, 1)
    with pytest.raises(ValueError):
        sweep_of(10)


def test_sweeps_are_uniform_and_mirror_each_other():
    lay = SweepLayout(mirror_sum=16.0)
    a, b = robot_xy(lay, 1, 0, np.arange(16)), robot_xy(lay, 1, 1, np.arange(16))
    assert a[0, 1] == pytest.approx(lay.centre_y_mm + 30) and b[0, 1] == pytest.approx(lay.centre_y_mm - 30)
    assert np.allclose(np.diff(a[:, 1]), -3.75) and np.allclose(np.diff(b[:, 1]), 3.75)
    assert a[4, 1] == pytest.approx(b[12, 1])  # k + j = m
    xs = silicone_poses(lay)[::2, 0, 0]
    assert np.allclose(xs, [-265, -300, -335, -370, -405])  # path 0 at +x (the map's left)
    assert silicone_poses(lay).shape == (10, 16, 2)


def synthetic_dots(layout: SweepLayout, vessels_y=(-20.0, 10.0), depth_mm=21.0):
    """Dots of horizontal vessels seen through a camera whose true scale the estimator does not know."""
    dots = np.full((10, 16, 4, 2), np.nan)
    counts = np.zeros((10, 16), np.int16)
    poses = silicone_poses(layout)
    for v in range(10):
        for f in range(16):
            for y_w in vessels_y:
                y_cam = poses[v, f, 1] - y_w  # y_w = -y_cam + y_r
                px = DEFAULT_CAMERA.project(np.array([0.0, y_cam, depth_mm]))
                if abs(px[1] - 584) < 330:
                    dots[v, f, counts[v, f]] = px
                    counts[v, f] += 1
    return dots, counts


def test_mirror_sum_is_recovered_whatever_the_image_scale():
    truth = SweepLayout(mirror_sum=15.8)
    for depth in (16.0, 21.0):
        dots, counts = synthetic_dots(truth, depth_mm=depth)
        est = estimate_mirror(dots, counts, np.zeros(10))
        assert est["m"] == pytest.approx(15.8, abs=0.1)


def test_direction_evidence_signs():
    dots, counts = synthetic_dots(SweepLayout())
    markers = np.zeros((10, 16, 127, 2))
    markers[::2, ..., 1] -= 5  # skin dragged along the image motion
    ev = direction_evidence(markers, dots, counts, np.zeros(10))
    assert all(e["dot_step_px"] < 0 for e in ev[::2]) and all(e["dot_step_px"] > 0 for e in ev[1::2])
    assert all(e["marker_drift_px"] < 0 for e in ev[::2])


def test_no_dots_is_a_clear_error():
    with pytest.raises(ValueError, match="mirror sum"):
        estimate_mirror(np.zeros((10, 16, 4, 2)), np.zeros((10, 16), int), np.zeros(10))


def test_real_sweeps_land_on_the_photo_vessels(real_sets):
    SILICONE = real_sets["silicone"]
    from palpation.mapping.silicone_check import pose_check

    with np.load(SILICONE) as z:
        d = {k: z[k] for k in ("markers", "labels", "dots", "dot_counts", "line_angle_deg")}
    mirror = estimate_mirror(d["dots"], d["dot_counts"], d["line_angle_deg"])
    assert 15.5 < mirror["m"] < 16.1
    lay = SweepLayout(mirror_sum=mirror["m"])
    args = (d["markers"], d["labels"], d["dots"], d["dot_counts"])
    good = pose_check(*args, lay)
    assert good["iou_video_photo"] > 0.2 and good["dots_to_photo_mm"]["mean"] < 1.0
    for wrong in (dict(path0_side=-1.0), dict(direction0_sign=1.0), dict(centre_y_mm=6.0)):
        bad = pose_check(*args, dataclasses.replace(lay, **wrong))
        assert bad["iou_video_photo"] < 0.6 * good["iou_video_photo"], wrong
