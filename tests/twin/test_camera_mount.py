"""Camera error, mount offset and marker anchor (residual loop), and the runner honouring them."""

import dataclasses

import numpy as np
import pytest

from palpation.camera import DEFAULT_CAMERA, Fisheye
from palpation.markers.template import rest_template
from palpation.twin.config import CameraConfig, MarkerConfig, MountConfig, TwinConfig
from palpation.twin.markers import (ImageSimilarity, bind_markers, bind_markers_through, body_to_camera,
                                    project_markers_np)
from palpation.twin.runner import EnvRequest, plan_requests, run_batch
from palpation.twin.trajectory import PHANTOM_TOP_M, mount_offset, plan_trajectory, tip_positions, with_mount


def test_similarity_is_a_camera_with_other_intrinsics():
    s = ImageSimilarity(1.04, 3.0, 5.0, -2.0)
    p = np.random.default_rng(0).normal(size=(20, 3)) * 0.005 + np.array([0, 0, 0.03])
    px = DEFAULT_CAMERA.project(p)
    assert np.allclose(s.inverse(s.apply(px)), px)
    # no rotation: exactly the fisheye with f * 1.04 and the principal point moved by (5, -2)
    s0 = ImageSimilarity(1.04, 0.0, 5.0, -2.0)
    other = Fisheye(f_px=380.0 * 1.04, cx_px=1045.0, cy_px=582.0)
    assert np.allclose(s0.apply(px), other.project(p), atol=1e-9)


def test_camera_binding_keeps_the_rest_and_scales_motion(mesh):
    t = rest_template()
    nominal = bind_markers(mesh.nodes, mesh.dome_nodes, t)
    through = bind_markers_through(mesh.nodes, mesh.dome_nodes, t, ImageSimilarity(1.05, 4.0, 10.0, 0.0))
    T = np.eye(4)[None]
    rest = through.markers(project_markers_np(through.binding, mesh.nodes[None], T)[0])
    assert np.allclose(rest, nominal.rest_px)  # the rest image is what the real rest photo fixes
    same = bind_markers_through(mesh.nodes, mesh.dome_nodes, t, ImageSimilarity())
    assert np.array_equal(same.binding.node_ix, nominal.node_ix)
    moved = mesh.nodes + np.array([0.0003, 0.0, 0.0])  # a small rigid slip of the dome in B
    d_nom = project_markers_np(nominal, moved[None], T)[0] - nominal.rest_px
    d_same = same.markers(project_markers_np(same.binding, moved[None], T)[0]) - nominal.rest_px
    assert np.allclose(d_same, d_nom)


def test_mount_offset_goes_deeper_and_tilts_about_the_tip():
    traj = plan_trajectory("press")
    deeper = with_mount(traj, mount_offset(dz_m=0.5e-3))
    assert (tip_positions(traj)[-1, 2] - tip_positions(deeper)[-1, 2]) == pytest.approx(0.5e-3, abs=1e-12)
    tilted = with_mount(traj, mount_offset(tilt_x_deg=3.0))
    assert np.allclose(tip_positions(tilted), tip_positions(traj), atol=1e-12)  # the tip stays put
    assert PHANTOM_TOP_M > tip_positions(deeper)[-1, 2]


def test_runner_honours_config_camera_and_mount(mesh):
    cfg = TwinConfig()
    moved = dataclasses.replace(cfg, mount=MountConfig(dz=0.3e-3, tilt_x_deg=1.0),
                                camera=CameraConfig(f_scale=1.05, rotation_deg=2.0))
    base_plan = plan_requests(mesh, cfg, [EnvRequest("press")])[0]
    plan = plan_requests(mesh, moved, [EnvRequest("press")])[0]
    assert np.allclose(plan.T_BA, base_plan.T_BA @ mount_offset(0.3e-3, 1.0, 0.0))
    a = run_batch(mesh, cfg, [EnvRequest("press")], progress=False, max_frames=6, device="cpu").records[0]
    b = run_batch(mesh, dataclasses.replace(cfg, camera=CameraConfig(f_scale=1.05)), [EnvRequest("press")],
                  progress=False, max_frames=6, device="cpu").records[0]
    assert np.allclose(a.rest_markers_px, b.rest_markers_px)  # anchored at the nominal rest
    assert np.isfinite(b.markers).all() and not np.allclose(a.markers, b.markers)
    assert np.allclose(body_to_camera(np.zeros(3)), [0, 0, 0.019])


def test_runner_anchors_markers_at_the_template(mesh):
    cfg = dataclasses.replace(TwinConfig(), markers=MarkerConfig(anchor=1.0))
    rec = run_batch(mesh, cfg, [EnvRequest("press")], progress=False, max_frames=2, device="cpu").records[0]
    assert np.allclose(rec.rest_markers_px, rest_template(), atol=1e-3)
    assert np.abs(rec.markers[0] - rest_template()).max() < 0.5  # two frames: still at rest
