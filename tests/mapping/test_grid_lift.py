"""Grid rules per dataset (SPEC §12) and the 2D -> 3D -> 2D lift."""

import numpy as np
import pytest

from palpation.camera import DEFAULT_CAMERA
from palpation.mapping.grid import Axis, Grid, check_grid_size, meat_grid, silicone_grid, sim_grid
from palpation.mapping.lift import PLANE_MM, rasterise, to_world

CENTRE = np.array([[DEFAULT_CAMERA.cx_px, DEFAULT_CAMERA.cy_px]])


def test_silicone_grid_rule():
    g = silicone_grid()
    assert g.shape == (100, 180)
    x, y = np.array([-425.0, -424.5, -245.01, -300.2]), np.array([-54.0, 45.9, 0.0, -10.7])
    r, c, inside = g.indices(np.stack([x, y], 1))
    assert c.tolist() == [179 - int(np.floor(v + 425)) for v in x]
    assert r.tolist() == [int(np.floor(v + 54)) for v in y]
    assert inside.all()
    assert not g.indices(np.array([[-244.0, 0.0]]))[2][0]


def test_meat_and_sim_grids_are_data_bounds_plus_3():
    pts = np.array([[-20.4, -330.2], [21.7, -210.0]])
    g = meat_grid(pts)
    assert g.rows.lo == -24 and g.rows.size == 22 + 3 - (-24)  # floor(-20.4)-3 .. ceil(21.7)+3
    r, c, inside = g.indices(pts)
    assert inside.all()
    assert c[1] == int(np.floor(g.cols.hi - (-210.0))) == 3  # col = floor(y_hi - y)
    s = sim_grid(pts)
    assert s.rows.mode == "up" and s.cols.mode == "up" and s.cols.lo == -334
    with pytest.raises(ValueError, match="no finite"):
        sim_grid(np.full((2, 2), np.nan))


def test_axis_centres_invert_the_index():
    for mode in ("up", "down", "mirror"):
        a = Axis(0, -10.0, 7, mode)
        assert a.index(a.centre_mm(np.arange(7))).tolist() == list(range(7))


def test_grid_size_limit():
    with pytest.raises(ValueError, match="max_grid_px"):
        check_grid_size(silicone_grid(), 10, 100_000, "A-to-B (silicone)")


def test_centre_pixel_lands_under_the_pose():
    px = CENTRE[None]  # (1, 1, 2)
    assert np.allclose(to_world("silicone", px, np.array([[-300.0, 5.0]])), [[[-300.0, 5.0]]])
    assert np.allclose(to_world("meat", px, np.array([[0.0, -285.0]])), [[[0.0, -285.0]]])
    T = np.eye(4)
    T[:3, :3] = np.diag([-1.0, 1.0, -1.0])
    T[:3, 3] = [0.039, 0.020, 0.012]
    assert np.allclose(to_world("sim", px, T[None]), [[[39.0, 20.0]]])


def test_axis_signs_follow_the_spec():
    right = CENTRE + [[100.0, 0.0]]  # +x_cam
    down = CENTRE + [[0.0, 100.0]]  # +y_cam
    x_cam = DEFAULT_CAMERA.unproject_to_plane(right, PLANE_MM["silicone"])[0, 0]
    sil = to_world("silicone", np.stack([right, down], 1), np.zeros((1, 2)))[0]
    assert sil[0, 0] == pytest.approx(x_cam) and sil[1, 1] == pytest.approx(-x_cam)  # y_w = -y_cam
    meat = to_world("meat", np.stack([right, down], 1), np.zeros((1, 2)))[0]
    assert meat[0, 1] > 0 and meat[1, 0] > 0  # x_w = y_cam, y_w = x_cam


def test_lengths_must_match():
    with pytest.raises(ValueError, match="3 prediction samples but 2 poses"):
        to_world("silicone", np.zeros((3, 127, 2)) + 1040, np.zeros((2, 2)))
    with pytest.raises(ValueError, match="unknown dataset"):
        to_world("pig", np.zeros((1, 1, 2)), np.zeros((1, 2)))


def test_rasterise_keeps_the_max_and_marks_truth():
    grid = Grid(Axis(0, 0.0, 4), Axis(1, 0.0, 3))
    world = np.array([[[0.2, 0.2], [0.7, 0.9], [3.5, 2.5], [9.0, 9.0]]])
    m = rasterise(grid, world, np.array([[0.3, 0.6, 0.1, 0.9]]), np.array([[0, 1, 0, 1]]), np.array([0]), 1)
    assert m.score[0, 0, 0] == pytest.approx(0.6) and m.truth[0, 0, 0]
    assert m.score[0, 3, 2] == pytest.approx(0.1) and not m.truth[0, 3, 2]
    assert m.visited.sum() == 2 and (m.score[~m.visited] == -1).all()
    assert m.dropped == 1  # the off-grid sample
