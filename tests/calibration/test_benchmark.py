"""The calibration benchmark runs end to end on a tiny configuration and reports its timings."""

import os

import numpy as np

from palpation.calibration.benchmark import bench_objective, preset
from palpation.markers.template import rest_template
from palpation.measured import MeasuredState, make_measured_set
from palpation.twin.config import TwinConfig
from palpation.twin.mesh import cached_sensor_mesh


def test_presets_match_the_conf_files():
    assert [p.name for p in preset("reference").params] == ["E", "k_n_ref"]
    assert preset("reference").fixed["c_n"] == 100.0 and preset("project").objective == "project"


def test_tiny_benchmark_record():
    mesh = cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))
    rest = rest_template().astype(np.float32)
    kinds = [("press", 4.0, None), ("twist_z", 4.0, 90.0), ("twist_x", 2.0, 20.0), ("slide", 3.0, None)]
    states = [MeasuredState(k, f"{k}.png", k, d, a) for k, d, a in kinds]
    mset = make_measured_set(np.stack([rest] * 4), np.ones((4, 127), bool), rest, states)
    rec = bench_objective("project", mesh, TwinConfig(), mset, n_trials=2, n_startup=1, device="cpu", max_frames=3)
    assert rec["study_trials"] == 2 and rec["trial_s"] > 0 and rec["study_s"] > 0 and rec["max_frames"] == 3
    assert rec["device"] == "cpu" and rec["resolution"] == "coarse" and rec["envs_per_trial"] == 4
