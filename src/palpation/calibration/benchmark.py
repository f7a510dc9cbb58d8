"""Calibration wall time: one trial and one 10-trial study (5 random in a batch + 5 GP) per objective.

A trial of the project objective is 4 vessel-free envs (press, twist_z, twist_x, slide); one of the
reference objective is a vessel-present slide to the trigger plus a vessel-free slide. Kernels are
loaded before timing. The study runs in a temporary SQLite file without MLflow, so its time is the
twin plus the sampler. SPEC §15.7: the reference took ~35 s per iteration, 493 s per 10-iteration run
(RTX 3080); the target is <= 3 s per trial on one H100 at the reference resolution.

    python -m palpation.calibration.benchmark --device cpu --resolution coarse
    python -m palpation.calibration.benchmark --device cuda --resolution reference
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
import time
from dataclasses import asdict, replace
from pathlib import Path

import warp as wp
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from palpation.calibration.config import CalibrationConfig, PaperParams
from palpation.calibration.study import build_objective, prepare, run_study
from palpation.io import save_json
from palpation.markers.template import rest_template
from palpation.measured import load_measured_set
from palpation.paths import REPO_ROOT
from palpation.tracking import git_commit
from palpation.twin.benchmark import device_name
from palpation.twin.config import TwinConfig
from palpation.twin.markers import bind_markers
from palpation.twin.mesh import SensorMesh

log = logging.getLogger(__name__)

PRESETS = ("project", "reference")  # conf/calibration/<name>.yaml


def preset(name: str) -> CalibrationConfig:
    """The calibration preset exactly as the app composes it, so the benchmark cannot drift from it."""
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return OmegaConf.to_object(compose(config_name="calibrate", overrides=[f"calibration={name}"]).calibration)


def bench_objective(kind: str, mesh: SensorMesh, twin: TwinConfig, mset, n_trials: int, n_startup: int,
                    device: str, max_frames: int | None = None) -> dict:
    """One record; `max_frames` cuts every trajectory (smoke tests only, recorded)."""
    cfg = replace(preset(kind), n_trials=n_trials, n_startup=n_startup, max_frames=max_frames)
    prep = prepare(cfg, twin, mset, source="measured set")
    binding = bind_markers(mesh.nodes, mesh.dome_nodes, rest_template())
    paper = {k: v for k, v in asdict(PaperParams()).items() if k in {p.name for p in cfg.params}}
    warm = build_objective(replace(prep, cfg=replace(cfg, max_frames=2)), mesh, binding, device)
    warm.evaluate([paper])  # loads (or compiles) every kernel outside the timing
    objective = build_objective(prep, mesh, binding, device)
    start = time.perf_counter()
    result = objective.evaluate([paper])[0]
    wp.synchronize_device(device)
    trial_s = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        study = run_study(prep, mesh, binding, Path(tmp), device, progress=False)
        study_s = time.perf_counter() - start
        batches = sorted({(t.user_attrs["wall_s/batch"], t.user_attrs["batch_size"]) for t in study.trials
                          if "wall_s/batch" in t.user_attrs})
        # a GP stuck on a bound re-proposes it; repeats are not simulated again (calibration.study)
        simulated = sum(not t.user_attrs.get("cached", 0.0) for t in study.trials)
    rec = {"objective": kind, "device": device_name(device), "resolution": mesh.resolution,
           "nodes": mesh.n_nodes, "tets": mesh.n_tets, "trial_s": trial_s,
           "trial_value_paper_params": result.value,
           "study_trials": n_trials, "study_trials_simulated": simulated, "study_startup": n_startup,
           "study_s": study_s,
           "study_s_per_trial": study_s / n_trials, "startup_batch_s": max((b for b, n in batches if n > 1),
                                                                          default=None),
           "envs_per_trial": 4 if kind == "project" else 2, "split_by_kind": cfg.split(device),
           "max_frames": max_frames, "commit": git_commit()}
    log.info("%s", rec)
    return rec


def main(argv: list[str] | None = None) -> list[dict]:
    # argparse, not a Hydra app (issue 16): a developer measurement outside the results DAG whose
    # flags are sizes, devices and repeats, not experiment config (nothing to compose or sweep)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda" if wp.is_cuda_available() else "cpu")
    parser.add_argument("--resolution", default="coarse", help="mesh: results/twin/mesh_<resolution>.npz")
    parser.add_argument("--mesh", type=Path, default=None, help="mesh file (default from --resolution)")
    parser.add_argument("--measured", type=Path, default=Path("results/data/photos/measured_photos"))
    parser.add_argument("--objectives", nargs="+", default=list(PRESETS), choices=PRESETS)
    parser.add_argument("--n-trials", type=int, default=10)
    parser.add_argument("--n-startup", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path("results/bench/calibration.json"))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(name)s %(message)s")
    mesh = SensorMesh.load(args.mesh or Path(f"results/twin/mesh_{args.resolution}.npz"))
    twin = TwinConfig(device=args.device)
    mset = load_measured_set(args.measured)
    records = []
    for kind in args.objectives:
        records.append(bench_objective(kind, mesh, twin, mset, args.n_trials, args.n_startup, args.device))
        save_json(args.out, records)  # rewritten after each objective: a long run keeps what it has
    print(json.dumps(records, indent=1))
    return records


if __name__ == "__main__":
    main()
