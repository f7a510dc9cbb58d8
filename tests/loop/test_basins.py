"""The camera's other basins as a start of the local finish (loop.basins), on a toy camera (no twin)."""

import numpy as np
import pytest

from palpation.loop.basins import CAM, camera_starts, nominal_steps, procrustes
from palpation.loop.config import LoopConfig
from palpation.loop.engine import Problem, initial_params
from palpation.loop.inputs import Target
from palpation.loop.refit import finish
from palpation.loop.simulate import State
from palpation.markers.template import rest_template

REST = rest_template().astype(np.float64)
Q = (REST - REST.mean(axis=0)) / 200.0
_rng = np.random.default_rng(5)
G, H, K, K2 = (_rng.normal(size=REST.shape) for _ in range(4))
OMEGA = 2 * np.pi / 30.0  # the binding's roughness: the displacement seen repeats every 30 px of principal point
AMP = {"a": 3.0, "b": 2.0, "h": 2.5}
TRUTH = {"cam_f_scale": 0.95, "cam_rotation_deg": -2.4, "cam_dx_px": 25.0, "cam_dy_px": 0.0}


def toy(state: State, p) -> np.ndarray:
    """markers = anchor + A (displacement sampled through the binding at the principal point), as
    twin.markers.CameraBinding: exactly linear in A, rough (periodic) in the principal point."""
    dx, dy = p["cam_dx_px"], p["cam_dy_px"]
    disp = AMP[state.name] * (Q + np.cos(OMEGA * dx) * G + np.sin(OMEGA * dx) * H + 0.05 * dx * K + 0.05 * dy * K2)
    a = np.radians(p["cam_rotation_deg"])
    A = p["cam_f_scale"] * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return REST + disp @ A.T


def simulate(jobs):
    return np.stack([toy(s, p) for s, p in jobs]), np.zeros(len(jobs), bool)


def test_procrustes_recovers_a_scaled_rotation():
    d = _rng.normal(size=(200, 2))
    a = np.radians(7.0)
    y = 0.9 * d @ np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]).T
    ca, cb, rss = procrustes(y, d)
    assert np.hypot(ca, cb) == pytest.approx(0.9) and np.degrees(np.arctan2(cb, ca)) == pytest.approx(7.0)
    assert rss < 1e-20


@pytest.mark.parametrize("basins", [False, True])
def test_the_finish_leaves_a_wrong_camera_basin_only_with_the_grid_start(basins):
    rng = np.random.default_rng(0)
    truth = initial_params(TRUTH)
    targets = [Target(State(n, "press", 2.0), toy(State(n, "press"), truth) + rng.normal(0, 0.05, REST.shape),
                      n != "h") for n in AMP]
    start = initial_params({"cam_dx_px": -5.0})  # the search's best: the neighbouring basin (30 px away)
    p = Problem("toy", "k", targets, dict(start), list(CAM), candidates=[])
    cfg = LoopConfig(polish_iters=6, polish_starts=1, final_refit_starts=1, camera_basins=basins).validate()
    fits = {"toy": {"ranked": [dict(start)]}}
    finish(cfg, [p], fits, simulate, {"toy"})
    if basins:
        assert abs(p.params["cam_dx_px"] - 25.0) < 1.0 and abs(p.params["cam_f_scale"] - 0.95) < 0.005
        assert abs(p.params["cam_rotation_deg"] + 2.4) < 0.2 and fits["toy"]["polish"]["chains"] == 2
    else:
        assert abs(p.params["cam_dx_px"] - 25.0) > 20.0 and fits["toy"]["polish"]["chains"] == 1


def test_only_problems_that_search_the_camera_get_a_grid():
    p = Problem("nocam", "k", [], initial_params({}), ["E"], candidates=[])
    assert camera_starts([p], simulate, {"nocam": None}, nominal_steps({})) == {}
    assert nominal_steps({}) == {"cam_dx_px": 20.0, "cam_dy_px": 20.0}
