"""The Snakemake DAG: a dry run on the checkout lists every stage and touches nothing."""

import os
import subprocess
import sys
from pathlib import Path

from palpation.paths import REPO_ROOT

SNAKEMAKE = [sys.executable, "-m", "snakemake"]


def dry_run(tmp_path: Path, *args: str) -> str:
    """Dry-run the workflow in a copy of the checkout's workflow files (no results, no .snakemake)."""
    work = tmp_path / "wd"
    work.mkdir()
    for name in ("Snakefile", "workflow", "conf", "data"):
        os.symlink(REPO_ROOT / name, work / name)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    out = subprocess.run(SNAKEMAKE + ["--cores", "2", "-n", *args], cwd=work, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert not (work / "results").exists(), "a dry run must not create outputs"
    return out.stdout


def test_dry_run_lists_the_data_and_twin_rules(tmp_path):
    listing = dry_run(tmp_path)
    for rule in ("measured_photos", "silicone_set", "silicone_check", "meat_set", "data_summary",
                 "mesh", "simulate_canonical", "render_twin"):
        assert f"rule {rule}:" in listing or f"\n{rule} " in listing, f"{rule} missing from the DAG"


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
