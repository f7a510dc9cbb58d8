"""The frame-resident kernel (twin.integrator.kernel=resident) against the streamed kernels, on the CPU."""

import numpy as np
import pytest
import warp as wp

from palpation.twin.config import TwinConfig
from palpation.twin.resident import ResidentLayout, color_tets
from palpation.twin.simulator import BatchedTwin


DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])


def _press(mesh, kernel, frames=6, layout=None, block_dim=1, device="cpu"):
    """Two envs pressing 2 mm into the vessel (one without it): positions after each frame."""
    cfg = TwinConfig()
    cfg.integrator.kernel, cfg.integrator.block_dim = kernel, block_dim
    cfg.integrator.force_sum = "scatter" if device == "cpu" else "gather"  # mesh-order sums
    sim = BatchedTwin(mesh, 2, cfg, {"vessel": np.array([1.0, 0.0])}, device=device)
    if layout is not None:
        sim.resident = layout(sim)
    top = cfg.scene.phantom_top_z
    T = np.tile(np.eye(4), (2, 1, 1))
    T[:, :3, :3] = np.diag([1.0, -1.0, -1.0])  # dome down
    T[:, :3, 3] = [cfg.scene.vessel_center_x, cfg.scene.vessel_center_y, top + 0.0005]
    sim.reset(T)
    out = []
    for k in range(frames):
        T = T.copy()
        T[:, 2, 3] -= 0.0005
        sim.step_frame(T)
        out.append(sim.positions_world().copy())
    return np.array(out), sim


@pytest.mark.parametrize("cap", [None, 64])
def test_coloring_separates_force_nodes(mesh, cap):
    need = ~mesh.fixed | np.isin(np.arange(mesh.n_nodes), mesh.surface_nodes)
    order, start = color_tets(mesh.tets, need, cap)
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


def test_resident_rejects_layered_config():
    cfg = TwinConfig()
    cfg.integrator.kernel, cfg.damping.per_env = "resident", True
    with pytest.raises(ValueError, match="resident"):
        cfg.validate()
