"""Shared test fixtures: every test writes its outputs and MLflow store into a temp folder."""

import os

import pytest


@pytest.fixture
def results_tmp(tmp_path, monkeypatch):
    """Point results_dir() and the MLflow store at a fresh temp folder."""
    monkeypatch.setenv("PALPATION_RESULTS", str(tmp_path))
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    return tmp_path


@pytest.fixture(scope="session")
def real_sets(tmp_path_factory):
    """Paths of the real Silicone and Meat sets: the workflow's if built, else built here (~30 s)."""
    import subprocess
    import sys

    from palpation.paths import REPO_ROOT

    built = {"silicone": REPO_ROOT / "results/data/silicone/silicone.npz",
             "meat": REPO_ROOT / "results/data/meat/meat.npz"}
    if all(p.exists() for p in built.values()):
        return built
    out = tmp_path_factory.mktemp("real_sets")
    paths = {name: out / name / f"{name}.npz" for name in built}
    for name, path in paths.items():
        subprocess.run([sys.executable, "-m", f"palpation.apps.{name}", f"out.dir={path.parent}",
                        "track=false", f"hydra.run.dir={path.parent}"], cwd=REPO_ROOT, check=True,
                       capture_output=True, timeout=600)
    return paths


@pytest.fixture(scope="session")
def train_sets(tmp_path_factory):
    """Small synthetic Sim, Silicone and Meat sets (paths by name) for the training app's tests."""
    from palpation.graph.layout import rest_layout
    from palpation.graph.synthetic import write_meat, write_silicone, write_sim

    root, rest = tmp_path_factory.mktemp("train_sets"), rest_layout("ideal")
    return {"sim": str(write_sim(root / "sim", rest, n_traj=7, n_frames=72)),
            "silicone": str(write_silicone(root / "silicone.npz", rest, n_videos=2, n_frames=8)),
            "meat": str(write_meat(root / "meat.npz", rest, n_frames=(9,) * 5, n_val=2))}


@pytest.fixture(scope="session", autouse=True)
def no_slurm_controller_probe(tmp_path_factory):
    """Every snakemake process imports the SLURM executor plugin, which runs `scontrol show config` at import;
    where slurm-client is installed but no controller runs (workflow/scripts/slurm_local.sh stopped), that blocks
    ~9 s per call. No test talks to a controller (the SLURM profiles are only dry-run), so the tests see an
    `scontrol` that fails at once, as on a machine without SLURM (the plugin then falls back to its defaults)."""
    import shutil

    if shutil.which("scontrol") is None:
        yield
        return
    shim = tmp_path_factory.mktemp("no_slurm")
    (shim / "scontrol").write_text("#!/bin/sh\necho 'scontrol: no SLURM controller in the test suite' >&2\nexit 1\n")
    (shim / "scontrol").chmod(0o755)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PATH", f"{shim}:{os.environ['PATH']}")
        yield
