"""The frame-resident kernel (twin.integrator.kernel=resident) against the streamed kernels, on the CPU."""

import importlib.util
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
import warp as wp

from palpation.twin import resident
from palpation.twin.agreement import LAYERED, compare_devices
from palpation.twin.config import TwinConfig
from palpation.twin.mesh import shell_weights
from palpation.twin.resident import ResidentLayout, color_tets
from palpation.twin.resident_sync import chunk_table, pack_corners
from palpation.twin.simulator import BatchedTwin
from palpation.twin.thread_stress import press_frames


DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])
SHELL_M = 1.5e-3  # the loop's layered skin (loop.shell_thickness_mm)
# per env: a stiffer and a softer shell, more and less damping than the config's alpha (0.02)
LAYERED_ENVS = {"shell_ratio": np.array([3.0, 0.5]), "alpha": np.array([0.2, 0.05])}


def _press(mesh, kernel, frames=6, layout=None, block_dim=1, device="cpu", variant="tiles", coloring="mesh_order",
           layered=False, held=()):
    """Two envs pressing 2 mm into the vessel (one without it): positions after each frame.
    layered: the residual loop's layered elastic kernel with LAYERED_ENVS. held: frames stepped while this thread
    holds resident.CPU_TILES_LOCK (as another thread's twin would)."""
    cfg = TwinConfig()
    cfg.integrator.kernel, cfg.integrator.block_dim = kernel, block_dim
    cfg.integrator.resident_variant, cfg.integrator.resident_coloring = variant, coloring
    cfg.integrator.force_sum = "scatter" if device == "cpu" else "gather"  # mesh-order sums
    if layered:
        cfg.material.shell_thickness, cfg.damping.per_env = SHELL_M, True
    sim = BatchedTwin(mesh, 2, cfg, {"vessel": np.array([1.0, 0.0]), **(LAYERED_ENVS if layered else {})},
                      device=device)
    if layout is not None:
        sim.resident = layout(sim)
    return press_frames(sim, frames, held), sim


@pytest.mark.parametrize("cap,coloring", [(None, "mesh_order"), (64, "mesh_order"), (64, "largest_first")])
def test_coloring_separates_force_nodes(mesh, cap, coloring):
    need = ~mesh.fixed | np.isin(np.arange(mesh.n_nodes), mesh.surface_nodes)
    order, start = color_tets(mesh.tets, need, cap, coloring)
    assert sorted(order) == list(range(mesh.n_tets)) and start[-1] == mesh.n_tets
    assert cap is None or np.diff(start).max() <= cap
    for c in range(len(start) - 1):
        nodes = mesh.tets[order[start[c]:start[c + 1]]].reshape(-1)
        nodes = nodes[need[nodes]]
        assert len(np.unique(nodes)) == len(nodes), f"colour {c} repeats a force node"
    assert len(start) - 1 < 60  # a handful of colours, not a chain


def test_mesh_order_resident_equals_streamed_bit_for_bit(mesh):
    def mesh_order(sim):
        return ResidentLayout.for_mesh(mesh, sim.resident.need.numpy() != 0, sim.device, colored=False)

    ref, sim_ref = _press(mesh, "streamed")
    got, sim = _press(mesh, "resident", layout=mesh_order)
    assert sim.contact_flags()[0] and not sim.contact_flags()[1]
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(sim.contact_forces(), sim_ref.contact_forces())
    np.testing.assert_array_equal(sim.velocities_world(), sim_ref.velocities_world())


@pytest.mark.parametrize("device,block_dim", [("cpu", 1), ("cpu", 16)] + [(d, 256) for d in DEVICES[1:]])
def test_colored_resident_agrees_with_streamed(mesh, device, block_dim):
    """Colour order changes the float32 sums only; 16 cooperative CPU lanes exercise the barriers."""
    wp.config.enable_cpu_blocks = device == "cpu" and block_dim > 1
    try:
        ref, _ = _press(mesh, "streamed", device=device)
        got, sim = _press(mesh, "resident", block_dim=block_dim, device=device)
    finally:
        wp.config.enable_cpu_blocks = False
    moved = np.abs(ref[-1] - ref[0]).max()
    assert moved > 5e-4  # the press deformed the sensor
    assert np.abs(got - ref).max() < 1e-4 * moved  # rounding, not physics
    assert not sim.failed().any()


def test_kernel_config_is_checked():
    cfg = TwinConfig()
    cfg.integrator.kernel = "fast"
    with pytest.raises(ValueError, match="twin.integrator.kernel='fast'"):
        cfg.validate()
    cfg.integrator.kernel, cfg.damping.per_env = "resident", True
    cfg.validate()  # compact (the default variant) runs the layered kernel
    cfg.integrator.resident_variant = "tiles"
    with pytest.raises(ValueError, match="resident_variant in"):
        cfg.validate()
    cfg.integrator.resident_variant, cfg.contact.rule = "compact", "centroid"
    with pytest.raises(ValueError, match="contact.rule='sdf'"):
        cfg.validate()
    cfg.integrator.kernel = "auto"  # auto falls back to the streamed kernels instead
    cfg.validate()
    cfg.integrator.auto_min_envs = 0
    with pytest.raises(ValueError, match="auto_min_envs"):
        cfg.validate()


@pytest.fixture
def cpu_lanes():
    """Cooperative CPU lanes (fibers): a missing barrier changes the order of the sums, so the bits."""
    wp.config.enable_cpu_blocks = True
    yield 16
    wp.config.enable_cpu_blocks = False


@pytest.mark.parametrize("variant", ["onesync", "packed", "compact"])
def test_one_barrier_variants_equal_tiles_bit_for_bit(mesh, cpu_lanes, variant):
    """One barrier per colour chunk (and prefetched, packed constants) leave every add and its order."""
    ref, sim_ref = _press(mesh, "resident", block_dim=cpu_lanes)
    got, sim = _press(mesh, "resident", block_dim=cpu_lanes, variant=variant)
    assert sim.contact_flags()[0] and not sim.contact_flags()[1]
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(sim.velocities_world(), sim_ref.velocities_world())
    np.testing.assert_array_equal(sim.contact_forces(), sim_ref.contact_forces())


@pytest.mark.parametrize("variant", ["onesync", "packed", "compact"])
def test_one_lane_cpu_blocks_take_any_block_dim(mesh, variant):
    """Without cooperative CPU blocks a block has one lane whatever block_dim says (colours of <= 64)."""
    ref, _ = _press(mesh, "resident", block_dim=64, frames=2)
    got, _ = _press(mesh, "resident", block_dim=64, frames=2, variant=variant)
    np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("variant", ["atomic", "compact_atomic"])
def test_atomic_variants(mesh, cpu_lanes, variant):
    """One lane sums in colour order (the bits of tiles); 16 lanes differ by rounding only."""
    wp.config.enable_cpu_blocks = False
    ref, _ = _press(mesh, "resident", block_dim=64)
    one, _ = _press(mesh, "resident", block_dim=64, variant=variant)
    np.testing.assert_array_equal(one, ref)
    wp.config.enable_cpu_blocks = True
    got, sim = _press(mesh, "resident", block_dim=cpu_lanes, variant=variant)
    moved = np.abs(ref[-1] - ref[0]).max()
    assert 0 < np.abs(got - ref).max() < 1e-4 * moved and sim.contact_flags()[0]


def test_largest_first_coloring_agrees(mesh, cpu_lanes):
    ref, _ = _press(mesh, "streamed")
    got, _ = _press(mesh, "resident", block_dim=cpu_lanes, variant="packed", coloring="largest_first")
    assert np.abs(got - ref).max() < 1e-4 * np.abs(ref[-1] - ref[0]).max()


def test_packed_layout_round_trips():
    tets = np.array([[0, 1, 2, 3], [32767, 5, 40, 7]])
    need = np.zeros(32768, bool)
    need[[1, 40, 32767]] = True
    q = pack_corners(tets, need)
    fields = (q[:, None] >> (16 * np.arange(4, dtype=np.uint64))) & np.uint64(0xFFFF)
    np.testing.assert_array_equal(fields & np.uint64(0x7FFF), tets)
    np.testing.assert_array_equal(fields >> np.uint64(15) != 0, need[tets])
    with pytest.raises(ValueError, match="onesync"):
        pack_corners(np.array([[0, 1, 2, 32768]]), np.ones(32769, bool))
    starts, ends = chunk_table(np.array([0, 5, 6, 20]), cap=4)
    assert list(zip(starts, ends)) == [(0, 4), (4, 5), (5, 6), (6, 10), (10, 14), (14, 18), (18, 20), (0, 0)]


def test_resident_variant_names_are_checked():
    cfg = TwinConfig()
    cfg.integrator.resident_variant = "fast"
    with pytest.raises(ValueError, match="resident_variant"):
        cfg.validate()
    cfg.integrator.resident_variant, cfg.integrator.resident_coloring = "packed", "dsatur"
    with pytest.raises(ValueError, match="resident_coloring"):
        cfg.validate()


def _need(mesh):
    return ~mesh.fixed | np.isin(np.arange(mesh.n_nodes), mesh.surface_nodes)


def test_layered_mesh_order_resident_equals_streamed_bit_for_bit(mesh):
    """The layered per-tet arithmetic is the streamed kernel's own (layered_tet_forces): one lane in mesh order
    sums in the streamed scatter's order, so every bit agrees."""
    def mesh_order(sim):
        return ResidentLayout.for_mesh(mesh, _need(mesh), sim.device, colored=False, variant="compact",
                                       tet_shell=shell_weights(mesh.nodes, mesh.tets, SHELL_M))

    ref, sim_ref = _press(mesh, "streamed", layered=True)
    got, sim = _press(mesh, "resident", layout=mesh_order, block_dim=64, variant="compact", layered=True)
    plain, _ = _press(mesh, "streamed")
    assert np.abs(ref - plain).max() > 1e-6  # the shell and the per-env alpha act
    assert sim.contact_flags()[0] and not sim.contact_flags()[1]
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(sim.velocities_world(), sim_ref.velocities_world())
    np.testing.assert_array_equal(sim.contact_forces(), sim_ref.contact_forces())


@pytest.mark.parametrize("variant", ["compact", "packed"])
def test_layered_colored_resident_agrees_with_streamed(mesh, cpu_lanes, variant):
    """Colour order, 16 cooperative lanes: the layered sums differ from the streamed ones by rounding only."""
    ref, _ = _press(mesh, "streamed", layered=True)
    got, sim = _press(mesh, "resident", block_dim=cpu_lanes, variant=variant, layered=True)
    moved = np.abs(ref[-1] - ref[0]).max()
    assert moved > 5e-4 and sim.resident.layered
    assert np.abs(got - ref).max() < 1e-4 * moved and sim.contact_flags()[0]


def test_layered_agreement_over_a_short_slide(mesh, cpu_lanes):
    """python -m palpation.twin.agreement --layered on the CPU: the five trajectories' first 12 frames, phantom
    contact on, markers within float rounding (a missing shell would move them by pixels)."""
    res = compare_devices(mesh, ["cpu"], 12, ("streamed", "resident"), "compact", cpu_lanes, LAYERED)
    assert res["layered"] and res["resident_variant"] == "compact:mesh_order"
    assert res["max_px"] < 1e-3, res["per_trajectory"]
    assert all(v["contact_agreement"] == 1.0 for v in res["per_trajectory"].values())


@pytest.mark.parametrize("layered", [False, True])
@pytest.mark.parametrize("cpu_blocks", [False, True])
def test_auto_kernel_on_the_cpu_keeps_the_streamed_bits(mesh, layered, cpu_blocks):
    """auto on the CPU: the compact resident kernel, one lane in mesh order (even where cooperative CPU blocks
    are on and block_dim says 320), so every sum runs in the streamed scatter's order."""
    ref, sim_ref = _press(mesh, "streamed", layered=layered)
    wp.config.enable_cpu_blocks = cpu_blocks
    try:
        got, sim = _press(mesh, "auto", layered=layered, block_dim=320)
    finally:
        wp.config.enable_cpu_blocks = False
    assert sim.resident is not None and sim.resident.variant == "compact" and sim.resident.block_dim == 1
    assert sim.contact_flags()[0] and not sim.contact_flags()[1]
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(sim.velocities_world(), sim_ref.velocities_world())
    np.testing.assert_array_equal(sim.contact_forces(), sim_ref.contact_forces())


@pytest.mark.parametrize("layered", [False, True])
def test_auto_cpu_frame_runs_streamed_while_the_tiles_are_taken(mesh, layered):
    """A CPU frame under auto whose tile lock another thread holds runs the streamed kernels: the same bits, so
    resident and streamed frames mix freely (frames 1-3 streamed here)."""
    ref, _ = _press(mesh, "streamed", layered=layered)
    got, sim = _press(mesh, "auto", layered=layered, held=(1, 2, 3))
    assert set(sim._graphs) == {True, False}  # both kernels' frames ran
    np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("kernel", ["auto", "resident"])
def test_cpu_resident_twins_in_threads(mesh, kernel):
    """Warp's CPU tile kernels share one static pointer to their tiles: twins stepping side by side in threads
    (the loop's and the Sim-set writer's workers) never run them at once (resident.CPU_TILES_LOCK; under auto a
    frame that would wait runs streamed), each with its own bits."""
    ref, _ = _press(mesh, kernel, frames=4)
    with ThreadPoolExecutor(2) as pool:
        runs = list(pool.map(lambda _: _press(mesh, kernel, frames=4)[0], range(4)))
    for got in runs:
        np.testing.assert_array_equal(got, ref)


@pytest.mark.skipif(importlib.util.find_spec("gmsh") is None, reason="the centroid rule meshes the vessel")
def test_auto_kernel_on_the_cpu_needs_sdf_contact(mesh):
    cfg = TwinConfig()
    cfg.integrator.kernel, cfg.contact.rule = "auto", "centroid"
    assert BatchedTwin(mesh, 1, cfg, device="cpu").resident is None


def test_auto_kernel_choice_on_cuda(mesh, monkeypatch):
    """What auto picks on a CUDA device (a stand-in with an H100's 227 KB of shared memory a block)."""
    gpu = type("Gpu", (), {"is_cuda": True, "max_shared_memory_per_block": 232_448})()
    monkeypatch.setattr(resident.wp, "get_device", lambda device=None: gpu)
    need = _need(mesh)
    cfg = TwinConfig()
    cfg.integrator.kernel = "auto"  # default auto_min_envs 100: above every measured crossover (docs/twin.md)
    assert resident.runs_resident(cfg, need, "cuda:0", 100) and not resident.runs_resident(cfg, need, "cuda:0", 99)
    cfg.damping.per_env = True  # layered: compact has it
    assert resident.runs_resident(cfg, need, "cuda:0", 500)
    cfg.integrator.auto_min_envs = 64  # smaller batches stay streamed
    assert not resident.runs_resident(cfg, need, "cuda:0", 63) and resident.runs_resident(cfg, need, "cuda:0", 64)
    cfg.integrator.resident_variant = "onesync"  # no layered kernel: streamed
    assert not resident.runs_resident(cfg, need, "cuda:0", 64)
    cfg.integrator.resident_variant, cfg.contact.rule = "compact", "centroid"
    assert not resident.runs_resident(cfg, need, "cuda:0", 64)
    cfg.contact.rule = "sdf"
    gpu.max_shared_memory_per_block = resident.resident_shared_bytes("compact", mesh.n_nodes, int(need.sum()))
    assert not resident.runs_resident(cfg, need, "cuda:0", 64)  # no room for the static shared memory
    gpu.is_cuda = False
    cfg.integrator.kernel = "resident"  # an explicit choice stands (the CPU path of the tests above)
    assert resident.runs_resident(cfg, need, "cpu", 1)
