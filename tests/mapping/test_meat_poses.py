"""Meat slide timing from kinematic labels, on synthetic trials with a known slide."""

import numpy as np
import pytest

from palpation.camera import DEFAULT_CAMERA
from palpation.mapping.meat_poses import LABEL_CAMERA_MM, check_meat_poses, fit_meat_poses, straws_of
from palpation.markers.lattice import ideal_hex_lattice

REST = ideal_hex_lattice(55.0, 0.0, (1040.0, 584.0))


def trial(description, n_frames=26, speed=4.5, f0=12.2, straws=(-285.0,)):
    """Frames 2..T-3 as the set stores them; label = strip of 6 mm at each straw (camera 24 mm above)."""
    frames = np.arange(2, n_frames - 2)
    x_cam = DEFAULT_CAMERA.unproject_to_plane(REST, LABEL_CAMERA_MM)[:, 0]
    pose_y = -285.0 - speed * (frames - f0)
    labels = np.zeros((len(frames), 127), np.int8)
    for y in straws:
        labels |= (np.abs(x_cam[None] - (y - pose_y[:, None])) < 3.0).astype(np.int8)
    return {"markers": np.broadcast_to(REST, (len(frames), 127, 2)).copy(), "labels": labels,
            "frame": frames, "description": description}


def test_straw_counts_from_descriptions():
    assert straws_of("1 metal straw beneath 2 steaks") == 1
    assert straws_of("3 metal straws beneath 2 steaks") == 3
    assert straws_of("no straw") == 0


def test_fit_recovers_speed_and_crossing_frames():
    trials = [trial("1 metal straw beneath 1 steak"), trial("1 metal straw beneath 2 steaks", 25, f0=11.3),
              trial("1 metal straw on top", f0=12.0),
              trial("2 metal straws beneath 2 steaks", straws=(-275.0, -295.0)), trial("no straw", straws=())]
    fit = fit_meat_poses(trials)
    assert fit.speed_mm == pytest.approx(4.5, abs=0.1)
    assert fit.f0[0] == pytest.approx(12.2, abs=0.15) and fit.f0[1] == pytest.approx(11.3, abs=0.15)
    assert fit.f0[3] == pytest.approx(np.median([fit.f0[0], fit.f0[2]]))  # same length: median of 26-frame trials
    pose = fit.pose_xy(0, np.array([12.2]))
    assert pose[0, 0] == 0 and pose[0, 1] == pytest.approx(-285.0, abs=0.7)
    check = check_meat_poses(trials, fit)
    assert set(check) == {0, 1, 2, 3} and all(c["mean_mm"] < 3.0 for c in check.values())


def test_no_labels_is_a_clear_error():
    t = trial("1 metal straw beneath 1 steak")
    t["labels"][:] = 0
    with pytest.raises(ValueError, match="single-straw"):
        fit_meat_poses([t])
