"""The calibrate app on a tiny configuration: outputs, downstream loading, resume, MLflow, bad input."""

import csv
import os
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

import palpation.twin.config  # noqa: F401  (registers base_twin)
from palpation.apps import calibrate as app
from palpation.calibration.outputs import twin_fit_overrides
from palpation.calibration.validate import COLUMNS
from palpation.markers.template import rest_template
from palpation.measured import MeasuredState, make_measured_set, save_measured_set
from palpation.paths import REPO_ROOT
from palpation.twin.mesh import cached_sensor_mesh

KINDS = [("press", 4.0, None), ("twist_z", 4.0, 90.0), ("twist_x", 2.0, 20.0), ("slide", 3.0, None)]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A coarse mesh and a synthetic photo set: the template nudged differently per interaction."""
    root = tmp_path_factory.mktemp("cal_inputs")
    cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE")).save(root / "mesh.npz")
    rest = rest_template().astype(np.float32)
    rng = np.random.default_rng(1)
    for name, kinds in (("full", KINDS), ("no_twist_x", [k for k in KINDS if k[0] != "twist_x"])):
        markers = np.stack([rest + rng.normal(0, 3, rest.shape) for _ in kinds]).astype(np.float32)
        states = [MeasuredState(f"{k}_photo", f"{k}.png", k, d, a) for k, d, a in kinds]
        save_measured_set(root / name, make_measured_set(markers, np.ones(markers.shape[:2], bool), rest, states))
    return root


def config(inputs, out, *extra):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return compose(config_name="calibrate", overrides=[
            "calibration=quick", "calibration.n_trials=3", "calibration.n_startup=2", "calibration.max_frames=4",
            f"mesh={inputs / 'mesh.npz'}", f"measured={inputs / 'full'}", "photos_dir=null", "progress=false",
            "track=false", f"out.dir={out}", *extra])


def test_outputs_downstream_resume_and_tracking(inputs, tmp_path, results_tmp):
    out = tmp_path / "cal"
    summary = app.run(config(inputs, out, "track=true"))
    for name in ("study.db", "trials.csv", "fitted_params.yaml", "twin_fit/fitted.yaml", "calibration.csv",
                 "calibration.md", "calibration.json", "history.png", "history.pdf", "fig4.png", "fig4.pdf"):
        assert (out / name).exists(), name
    rows = list(csv.DictReader((out / "calibration.csv").open()))
    assert tuple(rows[0]) == COLUMNS and [r["interaction"] for r in rows] == ["press", "twist_z", "twist_x", "slide"]
    assert summary["trials_completed"] == 3 and set(summary["fitted"]) == {"E"}

    # downstream: any app composing `twin` picks the fit up from the two overrides
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        sim = compose(config_name="simulate", overrides=twin_fit_overrides(out))
    assert sim.twin.material.E == pytest.approx(summary["fitted"]["E"])

    import mlflow
    run = mlflow.search_runs(experiment_names=["calibrate"]).iloc[0]
    history = mlflow.MlflowClient().get_metric_history(run.run_id, "mae_px/press")
    assert sorted(m.step for m in history) == [0, 1, 2]

    # resume: more trials extend the same study; the first three are not simulated again
    calls = []
    real = app.run_study.__globals__["build_objective"]

    def counting(*args, **kwargs):
        obj = real(*args, **kwargs)
        evaluate = obj.evaluate
        obj.evaluate = lambda proposals: calls.append(len(proposals)) or evaluate(proposals)
        return obj

    app.run_study.__globals__["build_objective"] = counting
    try:
        again = app.run(config(inputs, out, "calibration.n_trials=4"))
    finally:
        app.run_study.__globals__["build_objective"] = real
    assert again["study"] == summary["study"] and again["trials_completed"] == 4 and sum(calls) <= 1


@pytest.mark.parametrize("extra, match", [
    (["calibration.params=[{name: youngs, low: 1.0, high: 2.0}]"], "unknown parameter 'youngs'"),
    (["calibration.params=[{name: E, low: 1.0e6, high: 1.0e5}]"], "need low < high"),
    (["calibration.params=[{name: E, low: 0.0, high: 1.0e6}]"], "must be > 0"),
    (["+calibration.fixed.k_nn=1.0"], "unknown twin parameter"),
    (["calibration.holdout=wiggle"], "holdout='wiggle'"),
    (["measured=NO_TWIST_X"], r"no measured state for interaction\(s\) \['twist_x'\]"),
])
def test_bad_input_fails_before_any_simulation(inputs, tmp_path, monkeypatch, extra, match):
    extra = [e.replace("NO_TWIST_X", str(inputs / "no_twist_x")) for e in extra]

    def no_mesh(*args, **kwargs):
        raise AssertionError("the twin was set up before the input checks")

    monkeypatch.setattr(app.SensorMesh, "load", no_mesh)
    with pytest.raises(ValueError, match=match):
        app.run(config(inputs, tmp_path / "cal", *extra))
    assert not (tmp_path / "cal").exists()
