"""The one-call GPU driver of the transfer table (workflow/scripts/gpu_transfer.sh, transfer_commands.py): its
commands compose for every method, and a CPU tiny run goes teachers -> students -> transfer_table end to end."""

import csv
import json
import os
import shlex
import subprocess
import sys

import pytest

from palpation.apps.train import also_aligned, job_from_config
from palpation.paths import REPO_ROOT
from palpation.transfer.report import read_methods

from tests.apps.test_train_app import TINY, compose_train

SCRIPTS = REPO_ROOT / "workflow" / "scripts"
sys.path.insert(0, str(SCRIPTS))
import transfer_commands  # noqa: E402


def _lines(*args):
    out = subprocess.run([sys.executable, str(SCRIPTS / "transfer_commands.py"), *args], capture_output=True,
                         text=True, cwd=REPO_ROOT, env={**os.environ, "PYTHONPATH": str(REPO_ROOT / "src")})
    assert out.returncode == 0, out.stderr
    return out.stdout.splitlines()


def test_every_command_composes_and_covers_every_method_and_configuration():
    methods = read_methods(REPO_ROOT / "conf" / "transfer" / "methods.yaml")
    lines = _lines("--device", "cuda")
    scored = set()
    for line in lines:
        argv = shlex.split(line)
        assert argv[:3] == ["python3", "-m", "palpation.apps.train"]
        overrides = [a for a in argv[3:] if not a.startswith("hydra.")]
        cfg = compose_train(overrides)
        job = job_from_config(cfg)
        assert job.train.device == "cuda" and list(cfg.seeds) == [0, 1, 2, 3, 4] and job.clip_len == 5
        method = next(a for a in argv if a.startswith("hydra.run.dir=")).split("/")[-3]
        assert argv[-1].endswith(f"{method}/{job.config_name}/L5")
        assert job.train.select_metric == "ap"  # the selection rules compare checkpoint-split AP
        partners = [a for a in cfg.also_test if ".on_" in a]  # cross_real partners, not configurations
        configs = {job.config_name} | {a.split(":")[0] for a in cfg.also_test if a not in partners}
        aligned = [folder.name for *_, folder in also_aligned(cfg)]  # valid entries: the app's own check
        scored |= {(m, c) for m in [method, *aligned] for c in configs}
        if job.train.pseudo != "none" or job.train.select_on != "val":
            assert len(configs) == 1  # trained apart
        if job.train.select_on == "other_real_half" and job.config_name != "C-to-B":
            other = "meat" if job.test_on == "silicone" else "silicone"
            assert partners == [f"{job.config_name}.on_{other}:{other}"]  # its cross_real score's source
    want = {(m, c) for m, spec in methods.items() for c in spec.get("configs", ("A-to-B", "A-to-C", "C-to-B"))}
    assert scored == want and len(lines) == len(set(lines))
    assert not [ln for ln in lines for m, spec in methods.items() if "scored_with" in spec and f"/{m}/" in
                ln.split("hydra.run.dir=")[1]]  # a method scored with another's models trains nothing itself
    students = _lines("--stage", "students")
    assert students and all("recipe.pseudo_from=" in s for s in students)
    assert not [t for t in _lines("--stage", "teachers") if "recipe.pseudo_from=" in t]


def test_the_driver_script_is_valid_bash_and_refuses_a_bad_jobs_count(tmp_path):
    script = SCRIPTS / "gpu_transfer.sh"
    assert subprocess.run(["bash", "-n", str(script)]).returncode == 0
    out = subprocess.run(["bash", str(script), str(tmp_path)], capture_output=True, text=True, cwd=REPO_ROOT,
                         env={**os.environ, "JOBS": "0"})
    assert out.returncode == 2 and "JOBS=0" in out.stderr


@pytest.mark.slow
def test_tiny_cpu_run_end_to_end(train_sets, tmp_path):
    """Two methods (a teacher and its transductive student) x three configurations x three seeds at tiny size on
    the CPU through the driver, then the table; a second call skips every finished training."""
    runs = tmp_path / "runs"
    methods = tmp_path / "methods.yaml"
    methods.write_text(f"""methods:
  robust:
    about: teacher
    transductive: false
    overrides: [recipe=robust]
  robust_seqnorm:
    about: robust's models, each scored sequence normalised on its own clips
    transductive: true
    scored_with: robust
    overrides: [recipe=robust, recipe.align=meanstd, recipe.align_stats=test_sequence]
  student:
    about: transductive student, 2 of 3 seeds agreeing
    transductive: true
    overrides: [recipe=robust, recipe.select_on=other_real_half, recipe.pseudo=test_set, recipe.pseudo_min_agree=0.6,
                recipe.pseudo_from={runs / 'robust'}]
""")
    extra = " ".join(shlex.quote(o) for o in ["graph.rest=ideal", "model=compact", *TINY[1:],
                                               *(f"data.{k}={v}" for k, v in train_sets.items())])
    env = {**os.environ, "RUNS": str(runs), "METHODS": str(methods), "SEEDS": "0 1 2", "JOBS": "2", "DEVICE": "cpu",
           "CLIP_LEN": "3", "PYTHON": sys.executable, "EXTRA": extra, "CORES": "2",
           "PYTHONPATH": str(REPO_ROOT / "src")}
    out = tmp_path / "out"
    done = subprocess.run(["bash", str(SCRIPTS / "gpu_transfer.sh"), str(out)], capture_output=True, text=True,
                          cwd=REPO_ROOT, env=env, timeout=900)
    log = (out / "transfer.log").read_text()
    assert done.returncode == 0, done.stdout + log[-3000:]
    assert "teachers: 2 trainings" in log and "students: 3 trainings" in log
    rows = list(csv.DictReader(open(out / "transfer.csv")))
    assert {(r["config"], r["method"]) for r in rows} >= {(c, m) for c in ("A-to-B", "A-to-C", "C-to-B")
                                                          for m in ("robust", "robust_seqnorm", "student")}
    assert {r["transductive"] for r in rows if r["method"] in ("student", "robust_seqnorm")} == {"true"}
    assert (out / "transfer_runs.tgz").is_file()
    # the student chose on Meat's selection half and scored Meat's method half through its partner run
    student = json.loads((runs / "student" / "A-to-B" / "L3" / "seed0" / "metrics.json").read_text())
    partner = json.loads((runs / "student" / "A-to-B.on_meat" / "L3" / "seed0" / "metrics.json").read_text())
    assert student["selected_on"] == partner["selected_on"] == "meat half" and partner["test_on"] == "meat"
    assert student["selected_trials"] and student["selected_trials"] == sorted(student["selected_trials"])
    picked = json.loads((out / "transfer.json").read_text())["rows"]
    assert {tuple(r["chosen_on"]) for r in picked if r["method"] == "student" and r["config"] == "A-to-B"
            and r["selection"] == "cross_real"} == {("meat method half (A-to-B.on_meat)",)}
    again = subprocess.run(["bash", str(SCRIPTS / "gpu_transfer.sh"), str(out)], capture_output=True, text=True,
                           cwd=REPO_ROOT, env=env, timeout=300)
    assert again.returncode == 0 and "teachers: 0 trainings" in (out / "transfer.log").read_text()
    assert transfer_commands.finished(str(runs), read_methods(methods), "student", ["C-to-B"], [0, 1, 2], 3)


def test_a_method_scored_with_another_must_differ_from_it_in_the_alignment_only(tmp_path):
    base = """methods:
  robust: {about: a, transductive: false, overrides: [recipe=robust]}
  student: {about: b, transductive: false, overrides: [recipe=robust, recipe.select_on=other_real]}
"""
    good = "  aligned: {about: c, transductive: true, scored_with: robust, overrides: [recipe=robust, " \
           "recipe.align=coral, recipe.align_stats=test_set]}\n"
    path = tmp_path / "methods.yaml"
    path.write_text(base + good)
    methods = read_methods(path)
    assert transfer_commands.scored_with(methods, "robust", ["C-to-B"]) == ["aligned"]
    assert not [t for t in transfer_commands.trainings(methods) if t[0] == "aligned"]
    for bad, why in [("scored_with: student, overrides: [recipe=robust, recipe.align=coral]", "must be student's"),
                     ("scored_with: robust, overrides: [recipe=robust]", "must set recipe.align"),
                     ("scored_with: nobody, overrides: [recipe=robust, recipe.align=coral]", "name a method"),
                     ("scored_with: robust, overrides: [recipe=robust, recipe.lr=0.1, recipe.align=coral]",
                      "must be robust's")]:
        path.write_text(base + "  aligned: {about: c, transductive: true, " + bad + "}\n")
        with pytest.raises(ValueError, match=why):
            read_methods(path)


def test_the_committed_table_is_the_paper_record_and_has_the_issue_shape():
    """docs/results/transfer.csv is a copy of the paper record the results page reads; five seeds per row, the three
    configurations, one chosen row per (config, selection, transductive)."""
    ours = REPO_ROOT / "docs" / "results" / "transfer.csv"
    assert ours.read_bytes() == (REPO_ROOT / "docs" / "results" / "paper" / "transfer" / "transfer.csv").read_bytes()
    rows = list(csv.DictReader(open(ours)))
    assert list(rows[0]) == ["config", "method", "selection", "transductive", "chosen", "seeds", "ap_mean", "ap_std",
                             "auroc_mean", "pos_share_05"]
    assert {r["config"] for r in rows} == {"A-to-B", "A-to-C", "C-to-B"} and {r["seeds"] for r in rows} == {"5"}
    groups = {(r["config"], r["selection"], r["transductive"]) for r in rows}
    for g in groups:
        assert sum(r["chosen"] == "true" for r in rows if (r["config"], r["selection"], r["transductive"]) == g) == 1


def test_check_data_loads_the_named_sets_and_refuses_a_meat_set_without_its_layout(train_sets, tmp_path):
    def check(extra):
        return subprocess.run([sys.executable, str(SCRIPTS / "transfer_commands.py"), "--check-data", "--extra",
                               extra], capture_output=True, text=True, cwd=REPO_ROOT,
                              env={**os.environ, "PYTHONPATH": str(REPO_ROOT / "src")})
    good = check(" ".join(f"data.{k}={v}" for k, v in train_sets.items()))
    assert good.returncode == 0 and good.stdout == "", good.stderr
    alone = tmp_path / "meat.npz"  # the set copied without the layout JSON beside it
    alone.write_bytes(open(train_sets["meat"], "rb").read())
    bad = check(f"data.meat={alone}")
    assert bad.returncode == 1 and "Meat layout" in bad.stderr and bad.stderr.count("\n") == 1
    unknown = check("data.pork=x.npz")
    assert unknown.returncode == 1 and "data.pork" in unknown.stderr


def test_a_failed_training_shows_its_own_error_line(tmp_path):
    methods = tmp_path / "methods.yaml"
    methods.write_text("methods:\n  broken:\n    about: a training that fails at start\n    transductive: false\n"
                       "    overrides: [recipe=no_such_recipe]\n")
    env = {**os.environ, "RUNS": str(tmp_path / "runs"), "METHODS": str(methods), "SEEDS": "0", "JOBS": "1",
           "DEVICE": "cpu", "PYTHON": sys.executable, "CORES": "1", "PYTHONPATH": str(REPO_ROOT / "src")}
    done = subprocess.run(["bash", str(SCRIPTS / "gpu_transfer.sh"), str(tmp_path / "out")], capture_output=True,
                          text=True, cwd=REPO_ROOT, env=env, timeout=600)
    assert done.returncode == 1
    errors = [line for line in done.stdout.splitlines() if line.startswith("Error: broken_")]
    assert errors and "no_such_recipe" in errors[0], done.stdout
