"""The reference joint objective (SPEC §6.2 + errata): score, heading, apex node, trigger, a tiny run."""

import os

import numpy as np
import pytest

from palpation.calibration.reference import (ReferenceObjective, VesselGeometry, apex_node, centreline_trigger,
                                             heading_once, joint_score)
from palpation.markers.template import rest_template
from palpation.twin.config import TwinConfig
from palpation.twin.markers import bind_markers
from palpation.twin.mesh import cached_sensor_mesh
from palpation.twin.trajectory import plan_trajectory

Z_TOP = 0.014


def test_heading_drawn_once_with_seed_42():
    assert heading_once(42) == pytest.approx(8.2187, abs=1e-4)


@pytest.mark.parametrize("mae, q, q_free, expect", [
    (12.43, 0.0139, 0.0120, (0.95, 12.43 / 165)),
    (300.0, 0.0150, 0.0120, (1.0, 1.0)),  # both clamped
    (10.0, 0.0110, 0.0120, (0.0, 10 / 165)),  # below the free height: no reward
    (10.0, float("nan"), 0.0120, (0.0, 10 / 165)),  # no node over the vessel
    (10.0, 0.0130, 0.0145, (0.0, 10 / 165)),  # z_top <= q_free
])
def test_joint_score(mae, q, q_free, expect):
    vpn, van, value = joint_score(mae, q, q_free, Z_TOP)
    assert (vpn, van) == pytest.approx(expect) and value == pytest.approx(vpn - van)


def test_vessel_geometry_and_apex_node():
    v = VesselGeometry.from_config(TwinConfig())
    assert v.z_top == pytest.approx(Z_TOP) and v.y_range == pytest.approx((0.037, 0.041))
    nodes = np.array([[0.039, 0.030, 0.013], [0.040, 0.0395, 0.012], [0.039, 0.039, 0.0125], [0.01, 0.039, 0.014]])
    assert apex_node(nodes, np.array([0, 1, 2, 3]), v) == 2
    assert apex_node(nodes, np.array([0, 1]), v) == 1
    assert apex_node(nodes, np.array([0, 3]), v) == -1


def test_trigger_fires_when_the_centreline_nears_the_marker_centroid():
    traj = plan_trajectory("slide", heading_once(42))
    from palpation.twin.markers import centreline_A, project_points_np

    centre = np.full((1, 127, 2), [1040.0, 584.0])
    stop = centreline_trigger(55.0)
    fired = [bool(stop(f, centre, traj.T_BA[f][None])[0]) for f in range(traj.n_frames)]
    first = fired.index(True)
    d = np.linalg.norm(project_points_np(centreline_A(), traj.T_BA[first][None])[0] - [1040, 584], axis=1)
    assert 150 < first < 300 and d.min() < 55.0 and not any(fired[:first])


def test_tiny_run_scores_and_divergence():
    mesh = cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))
    binding = bind_markers(mesh.nodes, mesh.dome_nodes, rest_template())
    obj = ReferenceObjective(mesh, TwinConfig(), rest_template(), 8.22, fixed={"c_n": 100.0}, binding=binding,
                             device="cpu", max_frames=6)
    good, bad = obj.evaluate([{"E": 881400.0, "k_n_ref": 94908.0}, {"E": 1e11, "k_n_ref": 94908.0}])
    assert not good.diverged and -1.0 <= good.value <= 1.0 and good.metrics["triggered"] == 0.0
    assert good.metrics["trigger_frame"] == 5.0  # no trigger: the cap of the cut slide
    assert good.value == pytest.approx(good.metrics["vpn"] - good.metrics["van"])
    assert bad.diverged and bad.value == -1.0
