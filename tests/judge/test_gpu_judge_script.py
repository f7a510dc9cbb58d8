"""workflow/scripts/gpu_judge.sh (issue 12's judge on the GPU): its guards, without running Snakemake."""

import os
import re
import subprocess

import pytest

from palpation.paths import REPO_ROOT

SCRIPT = REPO_ROOT / "workflow" / "scripts" / "gpu_judge.sh"


def _run(wd, *args, **env):
    return subprocess.run(["bash", str(SCRIPT), *args], cwd=wd, capture_output=True, text=True, timeout=30,
                          env={**os.environ, **env})


def test_missing_carried_mesh_is_one_line_naming_the_file(tmp_path):
    (tmp_path / "conf").symlink_to(REPO_ROOT / "conf")
    out = _run(tmp_path, "out")
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert "results/twin/mesh_reference.npz missing" in out.stderr and "carry it" in out.stderr
    out = _run(tmp_path, "out", PROFILE="nope")
    assert out.returncode == 2 and "conf/workflow/nope.yaml" in out.stderr


def test_a_second_call_while_one_runs_only_waits_for_it(tmp_path):
    """The run is detached (workflow/scripts/device_run.sh): a second call re-attaches, reports its progress and
    waits LIMIT_S for it (exit 75: still running); it starts nothing."""
    (tmp_path / "conf").symlink_to(REPO_ROOT / "conf")
    for f in ("twin/mesh_coarse.npz", "twin/mesh_coarse.json", "data/photos/measured_photos.npz",
              "data/photos/measured_photos.json"):
        (tmp_path / "results" / f).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "results" / f).write_text("")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "snakemake.pid").write_text(str(os.getpid()))  # this test's process: alive
    (tmp_path / "out" / "snakemake.log").write_text("7 of 25 steps (28%) done\n")
    out = _run(tmp_path, "out", PROFILE="tiny", LIMIT_S="1")
    assert out.returncode == 75 and "already running" in out.stdout and "7 of 25 steps" in out.stdout
    assert "warp" not in out.stdout and not (tmp_path / "out" / "snakemake.rc").exists()  # nothing started


def test_targets_are_the_judge_outputs_of_the_rules():
    targets = set(re.findall(r"results/[\w/]+\.(?:csv|md|png|pdf)", SCRIPT.read_text().split("targets=")[1]
                             .split("\nif ")[0]))
    judge = (REPO_ROOT / "workflow" / "rules" / "common.smk").read_text()
    assert {"results/judge/twin_selection.csv", "results/loop_slides/loop_slides.csv"} <= targets
    for name in ("twin_selection.csv", "twin_selection.md", "slide_motion.png", "slide_motion.pdf", "drift_bounds.csv"):
        assert f"results/judge/{name}" in targets and name in judge  # JUDGE_FILES


def test_refuses_to_take_another_runs_lock(tmp_path):
    """With a lock in .snakemake/locks and a Snakemake process alive in the same folder (here a stand-in named like
    one), the script does not unlock: it names the fix in one line and leaves the lock."""
    (tmp_path / "conf").symlink_to(REPO_ROOT / "conf")
    for f in ("twin/mesh_coarse.npz", "twin/mesh_coarse.json", "data/photos/measured_photos.npz",
              "data/photos/measured_photos.json"):
        (tmp_path / "results" / f).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "results" / f).write_text("")
    (tmp_path / ".snakemake" / "locks").mkdir(parents=True)
    (tmp_path / ".snakemake" / "locks" / "0.input.lock").write_text("x")
    other = subprocess.Popen(["bash", "-c", 'exec -a "python3 -m snakemake --workflow-profile other" sleep 30'],
                             cwd=tmp_path)  # a run in this checkout (one in another folder is no matter)
    try:
        out = _run(tmp_path, "out", PROFILE="tiny", PYTHONPATH=str(REPO_ROOT / "src"))
    finally:
        other.kill()
    if "warp" not in out.stdout:  # no Warp here: the script stops before the lock check
        pytest.skip("needs warp importable by python3")
    mine = [line for line in out.stderr.splitlines() if line.startswith("gpu_judge:")]  # Warp may warn too
    assert out.returncode == 4 and len(mine) == 1 and "its own copy" in mine[0]
    assert (tmp_path / ".snakemake" / "locks" / "0.input.lock").exists()
