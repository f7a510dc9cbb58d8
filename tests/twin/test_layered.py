"""Layered skin and per-env damping (residual loop): shell weights, kernel equality at ratio 1, stiffening."""

import dataclasses

import numpy as np
import pytest

from palpation.twin.config import TwinConfig
from palpation.twin.mesh import shell_weights, skin_depth_m, tet_volumes
from palpation.twin.runner import EnvRequest, plan_requests
from palpation.twin.simulator import BatchedTwin


def layered(cfg: TwinConfig, thickness=1.5e-3) -> TwinConfig:
    return dataclasses.replace(cfg, material=dataclasses.replace(cfg.material, shell_thickness=thickness),
                               damping=dataclasses.replace(cfg.damping, per_env=True))


def test_skin_depth_and_shell_fraction(mesh):
    # the dome tip is on the skin, a point 2 mm inside the tip is 2 mm deep, the flange is never skin
    depth = skin_depth_m(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.002]]))
    assert depth == pytest.approx([0.0, 0.002], abs=1e-9)
    assert np.isinf(skin_depth_m(np.array([0.0, 0.0, -0.015])))
    w = shell_weights(mesh.nodes, mesh.tets, 1.0e-3)
    vol = tet_volumes(mesh.nodes, mesh.tets)
    frac = (w * vol).sum() / vol.sum()
    assert 0.05 < frac < 0.15  # ~1 mm over ~1900 mm^2 of cap and wall in 18,400 mm^3
    assert np.all(shell_weights(mesh.nodes, mesh.tets, 0.0) == 0)


def run_press(mesh, cfg, params, frames=30):
    traj = plan_requests(mesh, cfg, [EnvRequest("press")])[0]
    n = len(next(iter(params.values()))) if params else 1
    sim = BatchedTwin(mesh, n, cfg, {**params, "k_s": 2e3}, device="cpu")
    sim.reset(np.repeat(traj.T_BA0[None], n, axis=0))
    for f in range(frames):
        sim.step_frame(np.repeat(traj.T_BA[f][None], n, axis=0))
    return sim.positions_world()


def test_layered_kernel_equals_reference_at_ratio_one(mesh):
    cfg = dataclasses.replace(TwinConfig(),
                              contact=dataclasses.replace(TwinConfig().contact, phantom_contact=True))
    ref = run_press(mesh, cfg, {}, frames=12)
    lay = run_press(mesh, layered(cfg), {"shell_ratio": [1.0], "alpha": [cfg.damping.alpha]}, frames=12)
    assert np.array_equal(ref, lay)  # bit for bit: the shell scale is exactly 1.0


def test_stiffer_shell_and_more_damping_change_only_their_env(mesh):
    cfg = layered(dataclasses.replace(TwinConfig(),
                                      contact=dataclasses.replace(TwinConfig().contact, phantom_contact=True)))
    x = run_press(mesh, cfg, {"shell_ratio": [1.0, 3.0, 1.0], "alpha": [0.02, 0.02, 0.2]}, frames=30)
    tip_z = x[:, np.argmax(mesh.nodes[:, 2]), 2]
    assert abs(tip_z[1] - tip_z[0]) > 1e-6 and abs(tip_z[2] - tip_z[0]) > 1e-7
    assert np.all(np.isfinite(x))


def test_extra_env_params_need_the_layered_kernel(mesh):
    with pytest.raises(ValueError, match="layered"):
        BatchedTwin(mesh, 2, TwinConfig(), {"shell_ratio": [1.0, 2.0]}, device="cpu")
    with pytest.raises(ValueError, match="shell_ratio must be > 0"):
        BatchedTwin(mesh, 1, layered(TwinConfig()), {"shell_ratio": [0.0]}, device="cpu")
    BatchedTwin(mesh, 1, TwinConfig(), {"alpha": TwinConfig().damping.alpha}, device="cpu")  # default: fine
