"""The loop app on a tiny configuration: outputs of both modes, the final twin loads downstream, bad input."""

import csv
import json
import os

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

import palpation.loop.config  # noqa: F401  (registers base_loop)
import palpation.twin.config  # noqa: F401  (registers base_twin)
from palpation.apps import loop as app
from palpation.loop.report import REAL_COLUMNS
from palpation.loop.selftest.fixed import COLUMNS as SELFTEST_COLUMNS
from palpation.markers.template import rest_template
from palpation.measured import MeasuredState, make_measured_set, save_measured_set
from palpation.paths import REPO_ROOT
from palpation.twin.mesh import cached_sensor_mesh

STATES = [MeasuredState("rest", "r.jpg", "rest", 0.0), MeasuredState("press_d4", "p.jpg", "press", 4.0),
          MeasuredState("twist_x_d2", "t.jpg", "twist_x", 2.0, 20.0)]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("loop_inputs")
    cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE")).save(root / "mesh.npz")
    rest = rest_template().astype(np.float32)
    rng = np.random.default_rng(2)
    markers = np.stack([rest, rest * 1.02 - 0.02 * np.array([1040, 584]), rest + rng.normal(0, 2, rest.shape)])
    good = make_measured_set(markers.astype(np.float32), np.ones((3, 127), bool), rest, STATES)
    save_measured_set(root / "good", good)
    return root


def config(inputs, out, *extra):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return compose(config_name="loop", overrides=[
            f"mesh={inputs / 'mesh.npz'}", f"measured={inputs / 'good'}", "track=false", f"out.dir={out}",
            "loop.max_frames=10", "loop.search.n_trials=2", "loop.search.n_startup=1", "loop.max_rounds=1",
            "loop.method.tries_per_round=1", "loop.effects=[surface_contact,camera]", "loop.holdout=[twist_x]",
            "loop.selftest.cases=[camera]", "loop.selftest.runs_per_case=1", "loop.selftest.max_rounds=1",
            "loop.selftest.states=[press,twist_x]", "loop.selftest.holdout=[twist_x]", *extra])


def test_real_and_selftest_outputs(inputs, tmp_path):
    out = tmp_path / "loop"
    res = app.run(config(inputs, out))
    for name in ("report.md", "loop_real.csv", "rounds.json", "twin_fit/fitted.yaml", "fitted_params.yaml",
                 "rounds.png", "rounds.pdf", "modes.png", "modes.pdf", "residuals/residual_press_d4.png",
                 "study.journal"):
        assert (out / name).exists(), name
    rows = list(csv.DictReader((out / "loop_real.csv").open()))
    assert tuple(rows[0]) == REAL_COLUMNS and rows[0]["round"] == "0" and rows[0]["effect_added"] == "none"
    assert json.loads((out / "rounds.json").read_text())["rounds"][0]["round"] == 0
    head = (out / "report.md").read_text().split("## Rounds")[0]  # issue 13.6: the verdict comes first
    for words in ("## Verdict", "Effects found", "search bound", "Remaining residual", "detector noise",
                  "No accuracy target applies", "Compensation guard", "Uncertainty (Laplace"):
        assert words in head, words
    tries = list(csv.DictReader((out / "tables" / "tries.csv").open()))  # tables as CSV, not Markdown
    assert tries[0]["effects"] == "calibrated twin" and len(tries) == len(res["rows"]) + sum(
        r["accepted"] == "False" for r in tries)
    for name in ("attribution", "per_state", "modes", "uncertainty", "final_check"):
        assert (out / "tables" / f"{name}.csv").exists(), name
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        sim = compose(config_name="simulate",
                      overrides=[f"hydra.searchpath=[file://{out}]", "+twin_fit=fitted"])
    assert sim.twin.material.E == pytest.approx(res["params"]["E"])
    from omegaconf import OmegaConf
    twin = OmegaConf.to_object(sim.twin)  # every field the loop writes is a TwinConfig field
    assert twin.integrator.dt == pytest.approx(1e-5) and twin.markers.anchor >= 0.0

    res = app.run(config(inputs, out, "mode=selftest"))
    rows = list(csv.DictReader((out / "loop_selftest.csv").open()))
    assert tuple(rows[0]) == SELFTEST_COLUMNS and rows[0]["effects_injected"] == "camera"
    assert (out / "selftest.md").exists() and (out / "selftest" / "sets" / "run_000.npz").exists()


def bad_set(path, markers=None, states=STATES, edit_json=None):
    rest = rest_template().astype(np.float32)
    m = np.stack([rest] * len(states)) if markers is None else markers
    save_measured_set(path, make_measured_set(m, np.ones(m.shape[:2], bool), rest, states))
    if edit_json:
        meta = json.loads(path.with_suffix(".json").read_text())
        edit_json(meta)
        path.with_suffix(".json").write_text(json.dumps(meta))
    return path


def _kind(meta):
    meta["states"][1]["trajectory"] = "poke"


def _nan(path):
    with np.load(path.with_suffix(".npz")) as z:
        arrays = dict(z)
    arrays["markers"][1, 5] = np.nan
    np.savez(path.with_suffix(".npz"), **arrays)


@pytest.mark.parametrize("make, overrides, match", [
    (lambda p: bad_set(p, edit_json=_kind), [], "unknown trajectory 'poke'"),
    (lambda p: (bad_set(p), _nan(p))[0], [], "NaN/inf"),
    (lambda p: p, [], "missing"),  # no such set
    (lambda p: bad_set(p), ["loop.holdout=[slide]"], "'slide' is neither a state name nor a trajectory kind"),
    (lambda p: bad_set(p), ["mode=replay"], "mode must be one of"),
])
def test_bad_input_fails_before_any_simulation(tmp_path, inputs, make, overrides, match):
    path = make(tmp_path / "bad")
    cfg = config(inputs, tmp_path / "out", f"measured={path}", "mesh=/nonexistent/mesh.npz", *overrides)
    with pytest.raises((ValueError, FileNotFoundError), match=match):
        app.run(cfg)


def test_wrong_marker_count_is_refused(tmp_path, inputs):
    path = tmp_path / "short"
    np.savez(path.with_suffix(".npz"), markers=np.zeros((3, 120, 2), np.float32),
             displacement=np.zeros((3, 120, 2), np.float32), rest=np.zeros((120, 2), np.float32),
             found=np.ones((3, 120), bool))
    bad_set(tmp_path / "ok")
    path.with_suffix(".json").write_text((tmp_path / "ok.json").read_text())
    with pytest.raises(ValueError, match="120 markers per state, expected 127"):
        app.run(config(inputs, tmp_path / "out", f"measured={path}", "mesh=/nonexistent/mesh.npz"))


def test_starting_twin_is_honoured_or_refused(inputs, tmp_path):
    """Issue 13.5: `twin.contact.phantom_contact=true twin.contact.k_s=2000` is the loop's start, not dropped."""
    out = tmp_path / "start"
    res = app.run(config(inputs, out, "loop.max_rounds=0", "twin.contact.phantom_contact=true",
                         "twin.contact.k_s=2000", "loop.method.round0_params=[E]"))
    rounds = json.loads((out / "rounds.json").read_text())
    assert rounds["effects"] == ["surface_contact"] and rounds["rounds"][0]["params_after"]["k_s"] == 2000.0
    assert "phantom_contact: true" in (out / "twin_fit" / "fitted.yaml").read_text()
    assert res["effects"] == ["surface_contact"]
    again = tmp_path / "again"  # the same start from the file the first run wrote
    app.run(config(inputs, again, "loop.max_rounds=0", f"start={out / 'twin_fit' / 'fitted.yaml'}"))
    assert json.loads((again / "rounds.json").read_text())["rounds"][0]["params_before"] is None
    assert json.loads((again / "rounds.json").read_text())["effects"] == ["surface_contact"]
    with pytest.raises(ValueError, match="twin.contact.mu=0.9 acts only with contact"):
        app.run(config(inputs, tmp_path / "bad", "twin.contact.mu=0.9"))


def test_loop_benchmark_writes_its_timing_and_refuses_a_failed_run(inputs, tmp_path):
    """workflow/scripts/bench_loop.py at toy sizes: one JSON record of one timed run; a failing loop, one line."""
    import subprocess
    import sys

    script = REPO_ROOT / "workflow" / "scripts" / "bench_loop.py"
    sizes = [f"mesh={inputs / 'mesh.npz'}", "loop.max_frames=10", "loop.search.n_trials=2", "loop.search.n_startup=1",
             "loop.holdout=[twist_x]"]
    out = tmp_path / "bench.json"
    run = subprocess.run([sys.executable, str(script), "--profile", "tiny", "--out", str(out),
                          f"measured={inputs / 'good'}", *sizes], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    record = json.loads(out.read_text())
    assert record["wall_s"] >= record["loop_s"] >= 0 and record["twin_s"] > 0 and record["cpu_affinity"] >= 1
    assert record["loop_real_csv"].startswith(",".join(REAL_COLUMNS))
    bad = subprocess.run([sys.executable, str(script), "--profile", "tiny", "--out", str(tmp_path / "b.json"),
                          f"measured={tmp_path / 'nowhere'}", *sizes], capture_output=True, text=True, timeout=600)
    assert bad.returncode != 0 and "bench_loop: the loop failed" in bad.stderr and not (tmp_path / "b.json").exists()
