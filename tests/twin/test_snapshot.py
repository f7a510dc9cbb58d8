"""run_until: per-env stop rules and snapshots agree with run_batch; per-env parameters reach the twin."""


import numpy as np
import pytest

from palpation.twin.config import TwinConfig
from palpation.twin.runner import EnvRequest, run_batch, simulate_states, tip_node_B
from palpation.twin.snapshot import run_until
from palpation.twin.trajectory import plan_trajectory


def test_stop_rule_and_last_frame(mesh, binding):
    reqs = [EnvRequest("press", name="a"), EnvRequest("twist_x", E=4e5, name="b"), EnvRequest("press", E=1e11)]
    snap = run_until(mesh, TwinConfig(), reqs, stop=lambda f, m, T: np.array([f == 3, False, False]),
                     last_frame=np.array([9, 6, 9]), binding=binding, device="cpu")
    assert list(snap.frame) == [3, 6, -1] and list(snap.stopped_by_rule) == [True, False, False]
    assert list(snap.failed) == [False, False, True] and np.isnan(snap.markers[2]).all()
    assert snap.frames == 7  # stops once every env is done
    full = run_batch(mesh, TwinConfig(), reqs[:2], binding, device="cpu", progress=False, max_frames=7)
    assert np.abs(snap.markers[0] - full.records[0].markers[3]).max() < 1e-3
    assert np.abs(snap.markers[1] - full.records[1].markers[6]).max() < 1e-3
    assert snap.nodes_A.shape == (3, mesh.n_nodes, 3)


def test_last_frame_may_pass_the_trajectory_end(mesh, binding):
    snap = run_until(mesh, TwinConfig(), [EnvRequest("press")], last_frame=np.array([8]), binding=binding,
                     device="cpu", max_frames=5)
    last_pose = plan_trajectory("press", tip_B_m=tip_node_B(mesh)).T_BA[4]
    assert snap.frame[0] == 8 and np.allclose(snap.T_BA[0], last_pose)  # holds the cut press's last pose


def test_every_per_env_parameter_and_geometry_passes(mesh, binding):
    cfg = TwinConfig()
    base = {"vessel": False, "depth_mm": 2.0}
    reqs = [("press", base), ("press", {**base, "nu": 0.45, "k_t": 1.0, "mu": 0.3, "k_s": 1e3, "c_s": 1.0}),
            ("twist_x", {**base, "angle_deg": 10.0})]
    markers, failed = simulate_states(mesh, cfg, reqs, device="cpu", binding=binding, max_frames=12)
    split, _ = simulate_states(mesh, cfg, reqs, device="cpu", binding=binding, max_frames=12, split_by_kind=True)
    assert not failed.any() and np.array_equal(markers, split)  # envs are independent
    assert np.abs(markers[0] - markers[1]).max() > 1e-3  # nu acts even without contact
    res = run_batch(mesh, cfg, [EnvRequest("press", nu=0.45, k_s=1e3, depth_mm=2.0)], binding, device="cpu",
                    progress=False, max_frames=2)
    params = res.records[0].params
    assert params["nu"] == 0.45 and params["k_s"] == 1e3 and params["depth_mm"] == 2.0
    assert params["k_t"] == cfg.contact.k_t and params["angle_deg"] is None
    with pytest.raises(ValueError, match="depth_mm=20"):
        simulate_states(mesh, cfg, [("press", {"depth_mm": 20.0})], binding=binding)
