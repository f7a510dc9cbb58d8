"""The Snakemake DAG: a dry run on the checkout lists every stage and touches nothing."""

import os
import re
import subprocess
import sys
from pathlib import Path

from palpation.paths import REPO_ROOT
from palpation.report.reproduction import job_stats

SNAKEMAKE = [sys.executable, "-m", "snakemake"]


def snakemake(tmp_path: Path, *args: str) -> str:
    """Run Snakemake in a fresh copy of the checkout's workflow files (no results, no .snakemake)."""
    work = tmp_path / "wd"
    work.mkdir(exist_ok=True)
    for name in ("Snakefile", "workflow", "conf", "data"):
        if not (work / name).exists():
            os.symlink(REPO_ROOT / name, work / name)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    out = subprocess.run(SNAKEMAKE + ["--cores", "2", *args], cwd=work, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert not (work / "results").exists(), "a dry run must not create outputs"
    assert sorted(p.name for p in work.iterdir() if p.name != ".snakemake") == sorted(
        ["Snakefile", "workflow", "conf", "data"]), "a dry run must not write into the working folder"
    return out.stdout + out.stderr


def dry_run(tmp_path: Path, *args: str) -> str:
    return snakemake(tmp_path, "-n", *args)


def test_dry_run_lists_the_whole_dag(tmp_path):
    """A fresh clone's dry run lists a job of every rule `rule all` depends on, and only those."""
    listing = dry_run(tmp_path)
    stats = job_stats(listing)
    graph = snakemake(tmp_path, "--rulegraph")  # DOT, one node per rule of the default target's DAG
    rules = set(re.findall(r'label = "(\w+)"', graph))
    assert set(stats) == rules, f"dry run lists {sorted(stats)}, the rule graph has {sorted(rules)}"
    # what `rule all` names (rules.<name>.output; TRAIN_REPORT_FILES is train_report's) plus their upstream
    rule_all = (REPO_ROOT / "Snakefile").read_text().split("rule all:")[1].split("\nrule ")[0]
    named = set(re.findall(r"rules\.(\w+)\.output", rule_all))
    upstream = {"mesh", "simulate_canonical", "simulate_vessel_slide", "simulate_dataset", "train",
                "train_report"}
    assert named | upstream | {"all"} == rules
    for rule in rules:
        assert f"rule {rule}:" in listing, f"{rule} has no job in the dry run's listing"


def test_unknown_profile_is_a_clear_error(tmp_path):
    work = tmp_path / "wd"
    work.mkdir()
    for name in ("Snakefile", "workflow", "conf", "data"):
        os.symlink(REPO_ROOT / name, work / name)
    out = subprocess.run(SNAKEMAKE + ["--cores", "1", "-n", "--config", "profile=nope"], cwd=work,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode != 0
    assert "unknown profile 'nope'" in out.stdout + out.stderr


def test_slurm_profile_dry_run(tmp_path):
    assert "simulate_canonical" in dry_run(tmp_path, "--workflow-profile",
                                           str(REPO_ROOT / "workflow/profiles/slurm"))
