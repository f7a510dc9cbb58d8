"""BatchedTwin on the coarse sensor: determinism, env independence, contact flags, divergence, configs."""

import importlib.util

import numpy as np
import pytest
import warp as wp
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from palpation.paths import REPO_ROOT
from palpation.twin.config import TwinConfig, from_reference_units
from palpation.twin.simulator import BatchedTwin

DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])
TOP = 0.015  # phantom top; the vessel axis is 3 mm below it at (x, 0.039), radius 2 mm


def dome_down(tip_z, y=0.039):
    """SPEC §4.1 orientation R_y(180) R_z(-10.37), tip at (0.039, y, tip_z)."""
    a, b = np.pi, np.deg2rad(-10.37)
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    Rz = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Ry @ Rz, [0.039, y, tip_z]
    return T


def press(sim, frames=24, depth=0.003, ys=None):
    """Tip from 1 mm above the phantom down to `depth` below it at <= 0.1 m/s, then hold."""
    ys = np.full(sim.n_envs, 0.039) if ys is None else ys
    z = lambda k: max(TOP + 0.001 - 0.1 * sim.frame_dt * k, TOP - depth)  # noqa: E731
    sim.reset(np.stack([dome_down(z(0), y) for y in ys]))
    flags = []
    for k in range(1, frames + 1):
        sim.step_frame(np.stack([dome_down(z(k), y) for y in ys]))
        flags.append(sim.contact_flags())
    return np.array(flags)


@pytest.mark.parametrize("device", DEVICES)
def test_same_inputs_same_results(mesh, device):
    runs = []
    for _ in range(2):
        sim = BatchedTwin(mesh, 2, TwinConfig(), {"k_n": [2e4, 5e3]}, device=device)
        press(sim, frames=12)
        runs.append(sim.positions_world())
    if device == "cpu" or sim.gather:
        np.testing.assert_array_equal(runs[0], runs[1])  # bit-identical: no float atomics
    else:
        np.testing.assert_allclose(runs[0], runs[1], atol=1e-6)  # GPU atomics reorder sums


@pytest.mark.parametrize("device", DEVICES)
def test_batched_envs_are_independent(mesh, device):
    params = {"E": [6e5, 881400.0, 1.2e6], "k_n": [1e4, 2e4, 3e3], "c_n": [0.0, 50.0, 100.0],
              "vessel": [1, 1, 0]}
    ys = np.array([0.039, 0.036, 0.042])
    batch = BatchedTwin(mesh, 3, TwinConfig(), params, device=device)
    press(batch, frames=12, ys=ys)
    single = BatchedTwin(mesh, 1, TwinConfig(), {k: v[1:2] for k, v in params.items()}, device=device)
    press(single, frames=12, ys=ys[1:2])
    tol = 0.0 if device == "cpu" else 1e-6
    np.testing.assert_allclose(batch.positions_world()[1], single.positions_world()[0], rtol=0, atol=tol)
    assert not np.allclose(batch.positions_world()[0] - batch.undeformed_world()[0],
                           batch.positions_world()[2] - batch.undeformed_world()[2])


@pytest.mark.parametrize("device", DEVICES)
def test_contact_flag_only_with_vessel(mesh, device):
    sim = BatchedTwin(mesh, 2, TwinConfig(), {"vessel": [1, 0]}, device=device)
    flags = press(sim, frames=24)
    assert not flags[0].any()  # 1 mm above the surface, 3 mm above the vessel
    assert flags[-1].tolist() == [True, False]
    f = sim.contact_forces()
    assert f[0, :, 2].sum() > 0 and np.all(f[1] == 0)  # pushes the dome up, away from the vessel
    assert np.all(f[0][~np.isin(np.arange(mesh.n_nodes), mesh.surface_nodes)] == 0)
    assert not sim.failed().any()


@pytest.mark.parametrize("device", DEVICES)
def test_divergence_marks_only_that_env(mesh, device):
    sim = BatchedTwin(mesh, 3, TwinConfig(), {"E": [881400.0, 1e12, 881400.0], "k_n": [2e4, 2e4, 1e10]},
                      device=device)
    press(sim, frames=24)
    assert sim.failed().tolist() == [False, True, True]
    sim.reset(np.stack([dome_down(0.02)] * 3))
    assert not sim.failed().any()
    x = sim.positions_world().reshape(-1, 3).copy()
    x[0] = [5.0, 0.0, 0.0]  # env 0: a runaway node
    tet = mesh.tets[0] + 2 * mesh.n_nodes  # env 2: invert one tet
    x[tet[0]], x[tet[1]] = x[tet[1]].copy(), x[tet[0]].copy()
    sim.x.assign(x)
    sim.check_health()
    assert sim.failed().tolist() == [True, False, True]


@pytest.mark.parametrize("device", DEVICES)
def test_scheduled_frames_equal_step_frame(mesh, device):
    """set_schedule + step_scheduled (one graph a frame, poses on the device) = step_frame per frame."""
    ys = np.array([0.039, 0.036])
    c, s = np.cos(0.01 * np.arange(25)), np.sin(0.01 * np.arange(25))  # a body yaw of 0.01 rad a frame
    yaw = lambda k: np.array([[c[k], -s[k], 0, 0], [s[k], c[k], 0, 0], [0, 0, 1, 0],  # noqa: E731
                              [0, 0, 0, 1]])
    z = lambda k: max(TOP + 0.001 - 0.1 * 1.24e-3 * k, TOP - 0.003)  # noqa: E731
    poses = np.stack([[dome_down(z(k), y) @ yaw(k) for y in ys] for k in range(25)])
    a, b = (BatchedTwin(mesh, 2, TwinConfig(), {"vessel": [1, 0]}, device=device) for _ in range(2))
    a.reset(poses[0])
    b.reset(poses[0])
    flags_a, flags_b = [], []
    for T in poses[1:]:
        a.step_frame(T)
        flags_a.append(a.contact_flags())
    b.set_schedule(poses[1:])
    for _ in poses[1:]:
        b.step_scheduled()
        flags_b.append(b.contact_flags())
    assert np.array(flags_a)[-1].tolist() == [True, False] and np.array_equal(flags_a, flags_b)
    tol = 0.0 if device == "cpu" else 1e-6
    np.testing.assert_allclose(b.positions_world(), a.positions_world(), rtol=0, atol=tol)
    np.testing.assert_array_equal(b.undeformed_world(), a.undeformed_world())
    assert b.frame == a.frame == 24 and np.array_equal(b.poses, poses[-1])
    with pytest.raises(ValueError, match="frames left"):
        b.step_scheduled()


def test_reset_twin_replays_its_graph_for_a_new_schedule(mesh):
    """A twin reset with new parameters and a schedule no longer than its last one keeps its graph and
    arrays (loop.simulate's pool) and ends bit for bit where a freshly built twin does; a longer schedule
    captures again."""
    def poses(n, speed, drift):  # down at `speed` m/s to 2 mm into the phantom, drifting in y at `drift` m/s
        z = [max(TOP + 0.001 - speed * 1.24e-3 * k, TOP - 0.002) for k in range(n)]
        return np.stack([[dome_down(z[k], y + drift * 1.24e-3 * k) for y in (0.039, 0.036)] for k in range(n)])

    used = BatchedTwin(mesh, 2, TwinConfig(), {"vessel": [1, 0]}, device="cpu")
    used.reset(poses(20, 0.1, 0.0)[0])
    used.set_schedule(poses(20, 0.1, 0.0)[1:])
    for _ in range(19):
        used.step_scheduled()
    graph, arrays = used._sched_graphs[False], used._sched_arrays  # False: the streamed kernels' graph
    for n, speed, drift, params in [(14, 0.2, 0.02, {"vessel": [0, 1], "E": [9e5, 1.6e6]}),
                                    (25, 0.15, -0.01, {"k_n": 5e3})]:
        fresh = BatchedTwin(mesh, 2, TwinConfig(), params, device="cpu")
        used.set_env_params(params)
        for twin in (fresh, used):
            twin.reset(poses(n, speed, drift)[0])
            twin.set_schedule(poses(n, speed, drift)[1:])
            for _ in range(n - 1):
                twin.step_scheduled()
        assert (used._sched_graphs.get(False) is graph and used._sched_arrays is arrays) == (n == 14)
        np.testing.assert_array_equal(used.positions_world(), fresh.positions_world())
        np.testing.assert_array_equal(used.contact_flags(), fresh.contact_flags())
        np.testing.assert_array_equal(used.failed(), fresh.failed())


@pytest.mark.parametrize("device", DEVICES)
def test_gather_equals_scatter(mesh, device):
    """Per-node slot sums (no atomics) add the same terms in the same order as the CPU's scatter."""
    runs = []
    for mode in ("scatter", "gather"):
        cfg = TwinConfig()
        cfg.integrator.force_sum = mode
        sim = BatchedTwin(mesh, 2, cfg, {"vessel": [1, 0], "k_n": [2e4, 5e3]}, device=device)
        assert sim.gather == (mode == "gather")
        flags = press(sim, frames=24)
        runs.append((sim.positions_world(), sim.contact_forces(), flags))
    tol = 0.0 if device == "cpu" else 1e-6
    np.testing.assert_allclose(runs[1][0], runs[0][0], rtol=0, atol=tol)
    np.testing.assert_allclose(runs[1][1], runs[0][1], rtol=0, atol=1e-3 if tol else 0.0)
    assert np.array_equal(runs[0][2], runs[1][2]) and runs[0][2][-1].tolist() == [True, False]


def test_bad_inputs_raise(mesh):
    with pytest.raises(ValueError, match="unknown env parameter"):
        BatchedTwin(mesh, 1, TwinConfig(), {"youngs": [1.0]})
    sim = BatchedTwin(mesh, 2, TwinConfig())
    with pytest.raises(ValueError, match=r"shape \(2, 4, 4\)"):
        sim.reset(np.eye(4)[None])
    with pytest.raises(ValueError, match="finite"):
        sim.set_env_params({"k_n": [1.0, np.nan]})
    with pytest.raises(ValueError, match="scalar or 2 values"):
        sim.set_env_params({"E": [1e6, 1e6, 1e6]})


@pytest.mark.parametrize("name", ["reference", "quick", "physical"])
def test_twin_configs_compose(name):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="mesh", overrides=[f"twin={name}"])
    twin = OmegaConf.to_object(cfg.twin).validate()
    assert isinstance(twin, TwinConfig)
    assert twin.frame_dt == pytest.approx(1.24e-3)
    assert twin.mesh.resolution == ("reference" if name != "quick" else "coarse")
    if name != "physical":
        assert twin.integrator.mass_scale == 25.0
        assert twin.contact.k_n == pytest.approx(from_reference_units(k_n=94908.307)["k_n"])


@pytest.mark.skipif(importlib.util.find_spec("gmsh") is None, reason="the centroid rule meshes the vessel")
def test_reference_centroid_rule_option(mesh):
    """SPEC §3.3 rule: vessel nodes vs nearest-centroid sensor triangles; same flags as the SDF."""
    cfg = TwinConfig()
    cfg.contact.rule = "centroid"
    sim = BatchedTwin(mesh, 2, cfg, {"vessel": [1, 0]})
    flags = press(sim, frames=24)
    assert not flags[0].any() and flags[-1].tolist() == [True, False]
    f = sim.contact_forces()
    on_tris = np.isin(np.arange(mesh.n_nodes), mesh.contact_tris)
    assert f[0, :, 2].sum() > 0 and np.all(f[0][~on_tris] == 0) and np.all(f[1] == 0)
    assert not sim.failed().any()


def mass_scale_pair(mesh):
    """The coarse sensor x5 with the reference's own coefficients and the SI model (mass_scale 25), both pressed
    2.7 mm into the vessel; returns (x5 twin, SI twin). Also run by workflow/scripts/twin_verification.py."""
    import dataclasses

    ref = TwinConfig()  # x5 lengths, reference coefficients, real masses of the scaled body
    ref.integrator.mass_scale, ref.damping.alpha = 1.0, 0.1
    ref.contact.k_n, ref.contact.c_n = 94908.307, 100.0
    s = ref.scene
    s.phantom_top_z, s.vessel_radius, s.vessel_length, s.vessel_depth = 0.075, 0.01, 0.2, 0.015
    s.vessel_center_x = s.vessel_center_y = 0.195
    big = BatchedTwin(dataclasses.replace(mesh, nodes=mesh.nodes * 5), 1, ref)
    phys = BatchedTwin(mesh, 1, TwinConfig())  # SI defaults: mass_scale 25, alpha and k_n / 5
    poses = [dome_down(TOP + 0.001 - 0.1 * phys.frame_dt * k) for k in range(30)]  # 2.7 mm deep
    scaled = [np.block([[T[:3, :3], 5 * T[:3, 3:]], [T[3:]]]) for T in poses]
    big.reset(scaled[0][None])
    phys.reset(poses[0][None])
    for Tb, Tp in zip(scaled[1:], poses[1:]):
        big.step_frame(Tb[None])
        phys.step_frame(Tp[None])
    return big, phys


def test_mass_scale_25_equals_the_reference_x5_length_scale(mesh):
    """docs/twin.md: a x5-length run with unscaled E, rho, k_n, c_n, alpha is mass_scale 25 in SI."""
    big, phys = mass_scale_pair(mesh)
    assert phys.contact_flags()[0] and big.contact_flags()[0]
    deflection = np.abs(phys.positions_world() - phys.undeformed_world()).max()
    # equal up to float32 round-off, which the contact amplifies to ~1e-3 of the deflection
    np.testing.assert_allclose(big.positions_world() / 5, phys.positions_world(), atol=5e-3 * deflection)
    np.testing.assert_allclose(big.contact_forces().sum(1) / 25, phys.contact_forces().sum(1), rtol=2e-2)
