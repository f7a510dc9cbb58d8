"""Marker binding (SPEC §5.2), the Warp projection kernels against numpy, and the label rule (§7)."""

import os
import numpy as np
import pytest
import warp as wp

from palpation.camera import DEFAULT_CAMERA
from palpation.markers.template import rest_template
from palpation.twin.markers import (
    MarkerProjector, bind_markers, body_to_camera, centreline_A, marker_labels, project_markers_np,
    project_points_np)
from palpation.twin.mesh import cached_sensor_mesh
from palpation.twin.trajectory import padded_schedule, plan_trajectory

DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])


@pytest.fixture(scope="module")
def coarse():
    return cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))


@pytest.fixture(scope="module")
def template():
    return rest_template()


def posed(mesh, T_BA):
    """Undeformed nodes of each env in the world: (n, N, 3)."""
    return np.einsum("nij,pj->npi", T_BA[:, :3, :3], mesh.nodes) + T_BA[:, None, :3, 3]


def test_rest_dome_projects_inside_356_px(coarse):
    px = DEFAULT_CAMERA.project(body_to_camera(coarse.nodes[coarse.dome_nodes]))
    assert np.linalg.norm(px - DEFAULT_CAMERA.centre, axis=1).max() < 356.0


def test_binding_weights(coarse, template):
    b = bind_markers(coarse.nodes, coarse.dome_nodes, template)
    assert b.node_ix.shape == (127, 5) and b.weights.shape == (127, 5)
    assert np.allclose(b.weights.sum(axis=1), 1.0) and np.all(b.weights > 0)
    assert np.isin(b.node_ix, coarse.dome_nodes).all()


@pytest.mark.parametrize("resolution, mean_px, max_px", [("coarse", 8.0, 20.0), ("reference", 3.5, 8.0)])
def test_rest_markers_reproduce_template_within_fit_residual(resolution, mean_px, max_px, template):
    mesh = cached_sensor_mesh(resolution, os.environ.get("PALPATION_MESH_CACHE"))
    b = bind_markers(mesh.nodes, mesh.dome_nodes, template)
    # measured: coarse 6.46 / 16.1 px, reference 2.78 / 6.67 px (mean / max); node spacing bounds it
    assert b.residual_px.mean() < mean_px and b.residual_px.max() < max_px
    T_BA = plan_trajectory("press").T_BA[[0, -1]]  # any rigid pose leaves the rest markers unchanged
    rest = project_markers_np(b, posed(mesh, T_BA), T_BA)
    assert np.abs(rest - b.rest_px).max() < 1e-6


@pytest.mark.parametrize("device", DEVICES)
def test_projection_kernel_matches_numpy(device, coarse, template):
    b = bind_markers(coarse.nodes, coarse.dome_nodes, template)
    trajs = [plan_trajectory("press"), plan_trajectory("twist_x"), plan_trajectory("slide", 9.0)]
    schedule, lengths = padded_schedule(trajs)
    first = np.array([0, 10, 81])
    proj = MarkerProjector(b, schedule, coarse.n_nodes, first, lengths, device=device)
    rng = np.random.default_rng(0)
    frames = [0, 35, 50, 97, 200, 397]
    nodes = {}
    for f in frames:
        # 0.5 mm random node noise on top of the rigid pose, different per env and frame
        x = posed(coarse, schedule[f]) + rng.normal(scale=5e-4, size=(3, coarse.n_nodes, 3))
        nodes[f] = x
        proj.extract(wp.array(x.reshape(-1, 3).astype(np.float32), dtype=wp.vec3, device=device), f)
    markers, centre = proj.results()
    for f in frames:
        for env in range(3):
            if not first[env] <= f < lengths[env]:
                continue
            ref_m = project_markers_np(b, nodes[f][env:env + 1], schedule[f, env:env + 1])[0]
            ref_c = project_points_np(centreline_A(), schedule[f, env:env + 1])[0]
            assert np.abs(markers[f - first[env], env] - ref_m).max() < 0.02  # float32 kernel
            assert np.abs(centre[f - first[env], env] - ref_c).max() < 0.02
    assert np.all(markers[lengths[0]:, 0] == 0)  # a finished env writes nothing


def test_centreline_under_the_tip_projects_to_the_centre():
    traj = plan_trajectory("slide")
    T = traj.T_BA[:1].copy()
    T[0, :3, 3] = [0.039, 0.039, 0.012]  # tip on the vessel axis apex (sim (0.195, 0.195, 0.060))
    px = project_points_np(centreline_A(), T)[0]
    assert np.linalg.norm(px[24:26].mean(0) - DEFAULT_CAMERA.centre) < 1.0  # apex between points 24, 25
    assert np.all(np.diff(px, axis=0) @ (px[-1] - px[0]) > 0)  # ordered along the axis


def test_label_rule():
    markers = np.zeros((2, 127, 2))
    markers[:, 0] = [29.9, 0.0]
    markers[:, 1] = [30.0, 0.0]
    markers[:, 2:] = [500.0, 500.0]
    line = np.zeros((2, 50, 2))
    line[:, :, 1] = np.linspace(-1000, -40, 50)[None]  # last point (0, -40): 40 px from the origin
    line[:, -1] = [0.0, 0.0]
    labels = marker_labels(markers, line, np.array([True, False]))
    assert labels.dtype == np.int8 and labels.shape == (2, 127)
    assert labels[0, 0] == 1 and labels[0, 1] == 0 and labels[0, 2:].sum() == 0
    assert labels[1].sum() == 0  # no contact, no positives


@pytest.mark.parametrize("device", DEVICES)
def test_kernel_is_precise_near_the_optical_axis(device, coarse, template):
    """The centre marker sits near the axis, where float32 acos(z/|p|) was ~0.1 px off."""
    b = bind_markers(coarse.nodes, coarse.dome_nodes, template)
    schedule, lengths = padded_schedule([plan_trajectory("press")])
    proj = MarkerProjector(b, schedule, coarse.n_nodes, np.array([0]), lengths, device=device)
    x = posed(coarse, schedule[0]) + np.random.default_rng(1).normal(scale=2e-5, size=(1, coarse.n_nodes, 3))
    proj.extract(wp.array(x.reshape(-1, 3).astype(np.float32), dtype=wp.vec3, device=device), 0)
    ref = project_markers_np(b, x, schedule[0])[0]
    assert np.abs(proj.results()[0][0, 0] - ref).max() < 2e-3


def test_label_rule_matches_the_direct_distance_bit_for_bit():
    """marker_labels' running minimum gives the labels of norm(m - c).min() < 30 exactly."""
    rng = np.random.default_rng(3)
    markers = (rng.random((40, 127, 2)) * 600).astype(np.float32)
    line = (rng.random((40, 50, 2)) * 600).astype(np.float32)
    angle = rng.random((40, 60)) * 2 * np.pi  # 60 markers within 1e-4 px of the 30 px circle
    radius = 30.0 + rng.normal(size=(40, 60)) * 1e-4
    markers[:, :60] = line[:, :1] + np.stack([radius * np.cos(angle), radius * np.sin(angle)], -1)
    contact = rng.random(40) > 0.2
    d = np.linalg.norm(markers[:, :, None, :] - line[:, None, :, :], axis=-1).min(axis=2)
    direct = ((d < 30.0) & contact[:, None]).astype(np.int8)
    assert np.array_equal(marker_labels(markers, line, contact), direct) and direct.sum() > 0
