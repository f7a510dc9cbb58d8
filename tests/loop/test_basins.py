"""The camera's other basins as a start of the local finish (loop.basins), on a toy camera (no twin)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from palpation.loop.basins import CAM, camera_starts, nominal_steps, procrustes
from palpation.loop.config import LoopConfig
from palpation.loop.inputs import Target
from palpation.loop.method import Method
from palpation.loop.problem import Problem, initial_params
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
    cfg = LoopConfig(method=Method(polish_iters=6, polish_starts=1, final_refit_starts=1, camera_basins=basins)).validate()
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
    assert nominal_steps({}) == {"cam_dx_px": 20.0, "cam_dy_px": 20.0, "cam_rotation_deg": 5.0}


# a miniature of the binding (twin.markers.bind_markers_through): a displacement field on jittered nodes
# 25 px apart, each marker bound by inverse distance to its 5 nearest nodes around S^-1(template), so the
# displacement seen is rough in the rotation as in the principal point (a 5 deg turn moves a rim marker ~26 px)
_node_rng = np.random.default_rng(11)
_g = np.arange(-400.0, 401.0, 25.0)
CENTRE = REST.mean(axis=0)
NODES = CENTRE + np.stack(np.meshgrid(_g, _g), -1).reshape(-1, 2) + _node_rng.uniform(-7.5, 7.5, (len(_g) ** 2, 2))
TREE = cKDTree(NODES)
ROUGH = _node_rng.normal(size=(3, len(NODES), 2)) / 3.0
TRUTH_ROT = {"cam_f_scale": 1.04, "cam_rotation_deg": -8.9, "cam_dx_px": 18.0, "cam_dy_px": 5.0}  # run 38's class


def toy_rot(state: State, p) -> np.ndarray:
    k = list(AMP).index(state.name)
    a, f = np.radians(p["cam_rotation_deg"]), p["cam_f_scale"]
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    bound = CENTRE + (REST - CENTRE - np.array([p["cam_dx_px"], p["cam_dy_px"]])) @ R / f  # S^-1(template)
    dist, idx = TREE.query(bound, k=5)
    w = 1.0 / np.maximum(dist, 1e-9)
    w /= w.sum(axis=1, keepdims=True)
    q = (NODES - CENTRE) / 200.0
    smooth = [q, np.stack([-q[:, 1], q[:, 0]], axis=1), q * (q ** 2).sum(axis=1, keepdims=True)][k]
    field = 3.0 * AMP[state.name] * (smooth + ROUGH[k])
    return REST + np.einsum("mk,mkc->mc", w, field[idx]) @ (f * R).T


def simulate_rot(jobs):
    return np.stack([toy_rot(s, p) for s, p in jobs]), np.zeros(len(jobs), bool)


@pytest.mark.parametrize("rotation", [False, True])
def test_a_strong_rotation_is_reached_only_with_the_rotation_axis(rotation):
    """Run 38's class (60-run self-test: rotation -8.9 deg): from the search's best at rotation 0 the
    principal-point grid ranks its points through the binding at rotation 0 and the finish stays in a wrong
    basin; with the rotation on the grid and three finer scans it starts in the truth's basin and reaches it."""
    rng = np.random.default_rng(1)
    truth = initial_params(TRUTH_ROT)  # noise 0.05 px per coordinate: a fit MAE of ~0.063 px
    targets = [Target(State(n, "press", 2.0), toy_rot(State(n, "press"), truth) + rng.normal(0, 0.05, REST.shape),
                      n != "h") for n in AMP]
    start = initial_params({})  # the search's best: the camera nominal
    p = Problem("toy", "k", targets, dict(start), list(CAM), candidates=[])
    cfg = LoopConfig(method=Method(polish_iters=6, polish_starts=1, final_refit_starts=1, camera_grid_rotation=rotation, camera_grid_refine=3 if rotation else 0)).validate()
    fits = {"toy": {"ranked": [dict(start)]}}
    finish(cfg, [p], fits, simulate_rot, {"toy"})
    err = {k: abs(p.params[k] - TRUTH_ROT[k]) for k in CAM}
    if rotation:
        assert err["cam_rotation_deg"] < 0.5 and err["cam_dx_px"] < 1.0 and err["cam_f_scale"] < 0.01, p.params
        assert fits["toy"]["polish"]["fit_end"] < 0.2
    else:
        assert err["cam_rotation_deg"] > 3.0 and fits["toy"]["polish"]["fit_end"] > 1.0, p.params


def test_the_old_grid_is_kept_with_the_rotation_axis_off():
    """rotation=False, refine=0 scans the principal point only (49 points at the current rotation, one call)."""
    calls = []

    def counting(jobs):
        calls.append(len(jobs))
        return simulate_rot(jobs)
    targets = [Target(State(n, "press", 2.0), toy_rot(State(n, "press"), initial_params(TRUTH_ROT)), n != "h")
               for n in AMP]
    p = Problem("toy", "k", targets, initial_params({}), list(CAM), candidates=[])
    camera_starts([p], counting, {"toy": None}, nominal_steps({}))
    assert calls == [2 * (2 + 49)]
    calls.clear()
    camera_starts([p], counting, {"toy": None}, nominal_steps({}), rotation=True, refine=3)
    assert calls == [2 * (2 + 49 * 7), *[2 * (2 + 27)] * 3]


@pytest.mark.parametrize("grid", [False, True])
def test_the_final_refit_leaves_a_wrong_rotation_basin_only_with_the_converged_grid(grid):
    """loop.method.camera_grid_converged: the final refit of a set with the camera also starts from the rotation grid
    at the final twin's physics; without it the LM chains stay in the wrong basin they start in."""
    from palpation.loop.refit import converge
    rng = np.random.default_rng(2)
    truth = initial_params(TRUTH_ROT)
    targets = [Target(State(n, "press", 2.0), toy_rot(State(n, "press"), truth) + rng.normal(0, 0.05, REST.shape),
                      n != "h") for n in AMP]
    p = Problem("toy", "k", targets, initial_params({}), list(CAM), candidates=[])
    p.markers = np.stack([toy_rot(t.state, p.params) for t in targets])
    log = converge([p], simulate_rot, None, 6, 2.0, camera_grid=grid)
    err = abs(p.params["cam_rotation_deg"] - TRUTH_ROT["cam_rotation_deg"])
    if grid:
        assert err < 0.5 and log["toy"]["after"]["fit"] < 0.2, p.params
    else:
        assert err > 3.0 and log["toy"]["after"]["fit"] > 1.0, p.params


@pytest.mark.parametrize("on", [False, True])
def test_a_null_try_with_the_camera_gets_the_rotation_grid_only_when_asked(on):
    """refit.finish: the problems named in `converged_basins` (the round's null tries) get the rotation grid's
    start with loop.method.camera_grid_converged, whatever the grid of the tries that add the camera."""
    rng = np.random.default_rng(3)
    truth = initial_params(TRUTH_ROT)
    targets = [Target(State(n, "press", 2.0), toy_rot(State(n, "press"), truth) + rng.normal(0, 0.05, REST.shape),
                      n != "h") for n in AMP]
    p = Problem("toy~null", "k", targets, initial_params({}), list(CAM), candidates=[])
    cfg = LoopConfig(method=Method(polish_iters=6, polish_starts=1, final_refit_starts=1, camera_grid_converged=on)).validate()
    fits = {p.name: {"ranked": [dict(p.params)]}}
    finish(cfg, [p], fits, simulate_rot, (), (), {p.name})
    assert fits[p.name]["polish"]["chains"] == (2 if on else 1)
    assert (abs(p.params["cam_rotation_deg"] - TRUTH_ROT["cam_rotation_deg"]) < 0.5) == on, p.params
