"""Compliant phantom (issue 12): Winkler foundation force vs indentation, and a vessel inclusion that
changes only the markers near it. The reference physics stays the default (test_reference_unchanged)."""

import dataclasses

import numpy as np
import pytest
import warp as wp
from scipy.spatial.transform import Rotation

from palpation.twin.config import TwinConfig
from palpation.twin.contact import eval_contact_forces
from palpation.twin.markers import project_points_np
from palpation.twin.mesh import box_mesh, projected_node_area
from palpation.twin.runner import EnvRequest, run_batch
from palpation.twin.simulator import BatchedTwin
from palpation.twin.trajectory import BASE_ROTATION, CENTRE_XY_M, PHANTOM_TOP_M

K_F = 2.0e7


def foundation_cfg(**scene) -> TwinConfig:
    cfg = TwinConfig()
    return dataclasses.replace(
        cfg, contact=dataclasses.replace(cfg.contact, phantom_contact=True, phantom_model="foundation", k_f=K_F,
                                         vessel=False),
        scene=dataclasses.replace(cfg.scene, **scene))


def phantom_force(mesh, cfg, rotation, tip_depth_m, env_params=None):
    """Total contact force on the rigid, undeformed mesh posed with its tip `tip_depth_m` below the top."""
    sim = BatchedTwin(mesh, 1, cfg, env_params or {})
    world = rotation.apply(mesh.nodes)
    world += np.array([*CENTRE_XY_M, PHANTOM_TOP_M - tip_depth_m]) - world[np.argmin(world[:, 2])]
    # on the twin's device (the config's, cpu), not Warp's default: on a CUDA machine that is cuda:0, and a launch
    # there with the twin's CPU arrays was an illegal memory access that broke every CUDA test after it
    dev = sim.device
    x = wp.array(world.astype(np.float32), dtype=wp.vec3, device=dev)
    zeros = wp.zeros(mesh.n_nodes, dtype=wp.vec3, device=dev)
    f_c = wp.zeros(mesh.n_nodes, dtype=wp.vec3, device=dev)
    wp.launch(eval_contact_forces, dim=sim.n_surface, device=dev,
              inputs=[x, zeros, zeros, sim.inv_mass, sim.surface, sim.n_surface, mesh.n_nodes, 0.0, sim.contact, 1],
              outputs=[f_c, sim.contact_flag])
    return f_c.numpy().astype(np.float64).sum(axis=0)


def test_flat_press_matches_the_foundation_value():
    mesh = box_mesh(size=(0.01, 0.01, 0.004), divisions=(4, 4, 2))  # flat 10 x 10 mm face at body z = 0
    area = projected_node_area(mesh)
    assert area.sum() == pytest.approx(1e-4, rel=1e-6)
    face_down = Rotation.from_euler("y", 180, degrees=True)
    for depth in (0.5e-3, 1e-3, 2e-3):
        f = phantom_force(mesh, foundation_cfg(), face_down, depth)
        assert f[2] == pytest.approx(K_F * 1e-4 * depth, rel=1e-5)  # p = k_f * delta over the face
        assert abs(f[0]) + abs(f[1]) < 1e-9 * f[2]
    assert phantom_force(mesh, foundation_cfg(), face_down, -1e-4)[2] == 0.0  # not touching


def test_dome_press_matches_the_spherical_cap_volume(mesh):
    # Winkler: F = k_f * displaced volume; the dome is a spherical cap (base radius a, height h)
    a, h = np.abs(mesh.nodes[mesh.dome_nodes, :2]).max(), -mesh.nodes[mesh.dome_nodes, 2].min()
    radius = (a * a + h * h) / (2 * h)
    for depth in (2e-3, 3e-3):
        f = phantom_force(mesh, foundation_cfg(), BASE_ROTATION, depth)
        volume = np.pi * depth ** 2 * (3 * radius - depth) / 3
        assert f[2] == pytest.approx(K_F * volume, rel=0.08)  # lumped nodes on a coarse mesh


def test_inclusion_stiffens_only_over_the_vessel():
    mesh = box_mesh(size=(0.01, 0.01, 0.004), divisions=(10, 10, 2))
    face_down = Rotation.from_euler("y", 180, degrees=True)
    x0, y0 = CENTRE_XY_M
    far = [[x0 - 0.05, y0 + 0.03, x0 + 0.05, y0 + 0.03]]  # 30 mm away: no effect at all
    near = [[x0 - 0.05, y0, x0 + 0.05, y0]]  # under the middle of the face
    params = {"incl_ratio": 20.0, "incl_depth": 0.002, "incl_diameter": 0.004}
    base = phantom_force(mesh, foundation_cfg(), face_down, 1e-3)[2]
    assert phantom_force(mesh, foundation_cfg(inclusions=far), face_down, 1e-3, params)[2] == base
    over = phantom_force(mesh, foundation_cfg(inclusions=near), face_down, 1e-3, params)[2]
    # springs in series over the band |y| < w = 2 mm: stiffer, bounded by the full-column value
    h = TwinConfig().scene.phantom_thickness
    assert base < over < base * 1 / (1 - (0.004 / h) * (1 - 1 / 20.0))
    assert phantom_force(mesh, foundation_cfg(inclusions=near), face_down, 1e-3, {**params, "incl_ratio": 1.0})[2] == base


def test_vessel_changes_only_nearby_markers(mesh, binding):
    x0, y0 = CENTRE_XY_M
    y_v = y0 + 0.008  # vessel 8 mm off the press centre, along x
    cfg = foundation_cfg(inclusions=[[x0 - 0.04, y_v, x0 + 0.04, y_v]])
    reqs = [EnvRequest("press", depth_mm=3.0, incl_ratio=r, incl_depth=0.002) for r in (1.0, 30.0)]
    res = run_batch(mesh, cfg, reqs, binding=binding, progress=False)
    assert not res.failed
    a, b = (r.markers[-1].astype(np.float64) for r in res.records)
    change = np.linalg.norm(b - a, axis=1)
    line = np.stack([np.linspace(x0 - 0.02, x0 + 0.02, 200), np.full(200, y_v), np.full(200, PHANTOM_TOP_M)], 1)
    line_px = project_points_np(line, res.records[1].T_BA[-1:])[0]
    dist = np.linalg.norm(a[:, None] - line_px[None], axis=-1).min(axis=1)
    assert change.max() > 0.1  # px: the vessel shows
    near, far = dist < 150, dist > 300
    assert near.any() and far.any()
    assert change[far].max() < 0.35 * change.max()
    assert change[near].mean() > 3 * change[far].mean()
