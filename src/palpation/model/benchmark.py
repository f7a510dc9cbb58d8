"""Wall time of seeds trained together (model.stacked) against the same seeds trained one after another.

Both sides run whole jobs as the workflow does (load the sets, train, score the test set, write the
four outputs), on the same data, in this one process, without MLflow; a short warm-up job first loads
the CUDA kernels so that neither side pays for it. The separate runs are sequential here: the paper
profile runs up to four jobs side by side on one GPU, so this is one configuration's speed-up, not the
profile's. The record lists each seed's test metrics from both sides and the largest |score
difference| per seed (model.stacked says why they differ at all).

    python -m palpation.model.benchmark --device cuda:0 --out docs/results/bench_train.json
    python -m palpation.model.benchmark --device cpu --out /tmp/b.json --sim <manifest.json> \\
        --override model=compact graph.rest=ideal train.train_batches=2 train.val_batches=1   # toy size
    python -m palpation.model.benchmark --device cuda:0 --synthetic 500 --out docs/results/bench_train.json
Inputs: the Sim set of `--sim` (default results/sim/dataset/manifest.json and the trajectory files it
lists) for A-to-A; other experiments also need their test set (data.silicone / data.meat overrides).
`--synthetic N` needs none: it writes N synthetic slides of `--frames` frames (palpation.graph.synthetic;
the paper's Sim set is 500 slides) and times on them; the times depend on the clip counts, not the values.
"""

from __future__ import annotations

import argparse
import logging
import platform
import sys
import tempfile
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch

from palpation.graph.layout import rest_layout
from palpation.graph.synthetic import write_sim
from palpation.io import save_json
from palpation.metrics.scores import load_scores
from palpation.model.job import TrainJob, device_name, job_from_settings, run_job, run_jobs_together
from palpation.paths import REPO_ROOT
from palpation.tracking import git_commit

log = logging.getLogger(__name__)
COMPARED = ("auroc", "ap", "fg_iou", "bg_iou", "mcc")


def compose_job(experiment: str, device: str, sim: str, overrides: list[str]) -> TrainJob:
    """The job exactly as the train app composes it (conf/train.yaml), so the benchmark cannot drift."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="train", overrides=[f"experiment={experiment}", f"device={device}",
                                                      f"data.sim={sim}", "track=false", *overrides])
    return job_from_settings(OmegaConf.to_container(cfg, resolve=True, enum_to_str=True))


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def bench(job: TrainJob, seeds: list[int], work: Path) -> dict:
    """Run both sides in `work` and return the record."""
    warm = replace(job, train=replace(job.train, epochs=1, train_batches=2, val_batches=1, patience=None))
    run_jobs_together([replace(warm, seed=s) for s in seeds[:2]], [work / "warm" / str(s) for s in seeds[:2]],
                      track=False)  # kernels, vmap's first trace and the allocator outside the timings
    _sync(job.train.device)
    apart, apart_s = [], []
    for s in seeds:
        t0 = time.perf_counter()
        apart.append(run_job(replace(job, seed=s), work / "apart" / f"seed{s}", track=False))
        _sync(job.train.device)
        apart_s.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    together = run_jobs_together([replace(job, seed=s) for s in seeds], [work / "together" / f"seed{s}"
                                                                         for s in seeds], track=False)
    _sync(job.train.device)
    together_s = time.perf_counter() - t0
    per_seed = []
    for s, a, t in zip(seeds, apart, together):
        pa = load_scores(work / "apart" / f"seed{s}" / "scores.npz").probs
        pt = load_scores(work / "together" / f"seed{s}" / "scores.npz").probs
        per_seed.append({"seed": s, "max_abs_score_diff": float(np.abs(pa - pt).max()),
                         "best_epoch": {"apart": a["best_epoch"], "together": t["best_epoch"]},
                         "test": {k: {"apart": a["test"][k], "together": t["test"][k]} for k in COMPARED},
                         "apart_wall_s": apart_s[seeds.index(s)], "apart_train_s": a["train_seconds"]})
    return {
        "what": f"{len(seeds)} seeds of {job.config_name} (L={job.clip_len}) trained together in one process "
                "(palpation.model.stacked) vs the same jobs one after another in this process",
        "device": device_name(job.train.device), "torch": torch.__version__, "python": platform.python_version(),
        "commit": git_commit(), "seeds": seeds,
        "job": {"config": job.config_name, "model": job.model.name, "clip_len": job.clip_len,
                "train": asdict(job.train), "n_clips": together[0]["n_clips"], "data": job.data},
        "wall_s": {"apart": sum(apart_s), "together": together_s, "speedup": sum(apart_s) / together_s},
        "train_s": {"apart": sum(a["train_seconds"] for a in apart),
                    "together": together[0]["trained_together"]["train_seconds"]},
        "test_s": {"apart": sum(a["test_seconds"] for a in apart),
                   "together": sum(t["test_seconds"] for t in together)},
        "max_abs_score_diff": max(r["max_abs_score_diff"] for r in per_seed),
        "per_seed": per_seed,
    }


def main(argv: list[str] | None = None) -> dict:
    # argparse, not a Hydra app (issue 16): a developer measurement outside the results DAG whose
    # flags are sizes, devices and repeats, not experiment config (nothing to compose or sweep)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--out", default="docs/results/bench_train.json")
    ap.add_argument("--experiment", default="A-to-A", help="conf/experiment/<name>.yaml")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--sim", default="results/sim/dataset/manifest.json", help="the Sim set's manifest")
    ap.add_argument("--override", nargs="*", default=[], help="more train-app overrides (key=value)")
    ap.add_argument("--synthetic", type=int, metavar="N", help="time on N synthetic slides instead of --sim")
    ap.add_argument("--frames", type=int, default=398, help="frames per synthetic slide")
    ap.add_argument("--keep", help="keep both sides' outputs in this folder (default: a temporary one)")
    args = ap.parse_args(argv)
    if args.device.startswith("cuda") and not torch.cuda.is_available():
        raise SystemExit(f"benchmark: error: --device {args.device} but torch sees no CUDA device; use --device cpu")
    if args.synthetic is None and not Path(args.sim).exists():
        raise SystemExit(f"benchmark: error: Sim manifest {args.sim} not found; run `snakemake "
                         f"{args.sim}` (rule simulate_dataset), pass --sim, or time on --synthetic 500")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    job = compose_job(args.experiment, args.device, args.sim, args.override)
    with tempfile.TemporaryDirectory() as tmp:
        if args.synthetic:
            t0 = time.perf_counter()
            sim = write_sim(Path(tmp) / "sim", rest_layout(job.rest), args.synthetic, args.frames)
            job = replace(job, data={**job.data, "sim": str(sim)})
            log.info("wrote %d synthetic slides in %.1f s", args.synthetic, time.perf_counter() - t0)
        record = bench(job, args.seeds, Path(args.keep or tmp))
    if args.synthetic:
        record["job"]["data"]["sim"] = (f"synthetic: {args.synthetic} slides x {args.frames} frames "
                                        "(palpation.graph.synthetic)")
    record["command"] = " ".join(["python -m palpation.model.benchmark", *(argv or sys.argv[1:])])
    save_json(args.out, record)
    log.info("%s: apart %.1f s, together %.1f s (x%.2f), max |score diff| %.2e", args.out,
             record["wall_s"]["apart"], record["wall_s"]["together"], record["wall_s"]["speedup"],
             record["max_abs_score_diff"])
    return record


if __name__ == "__main__":
    main()
