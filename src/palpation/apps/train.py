"""Hydra entry point: train one ST-GNN configuration x seed and score it (SPEC §8-§11).

    python -m palpation.apps.train experiment=A-to-B seed=0
    python -m palpation.apps.train --multirun experiment=A-to-B seed=0,1,2,3,4
    python -m palpation.apps.train experiment=A-to-B 'seeds=[0,1,2,3,4]' device=cuda   # one process
    python -m palpation.apps.train experiment=A-to-B 'seeds=[0,1]' 'also_test=[A-to-C:meat]' \
        hydra.run.dir=results/adhoc/train/A-to-B/L5        # one training, scored on Silicone and Meat
    python -m palpation.apps.train experiment=A-to-A seed=0 'also_test=[A-to-B:silicone]' \
        hydra.run.dir=results/adhoc/train/A-to-A/L5/seed0  # the same with one seed (no stacking)
    ... recipe=robust also_uncalibrated=results/adhoc/uncalibrated   # and its raw scores written there too
Outputs land in Hydra's run dir (metrics.json, scores.npz, pr.npz, checkpoint.pt) and in MLflow; with
`seeds`, seed s writes them to <run dir>/seed<s>/ (one MLflow run per seed all the same).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from palpation.config_check import app_main
from palpation.model.config import ModelConfig, TrainConfig
from palpation.model.gpu_slots import shared_cuda
from palpation.model.job import TrainJob, run_job, run_jobs_together

log = logging.getLogger(__name__)
RECIPE_KEYS = ("lr", "weight_decay", "focal_gamma", "norm_stats", "norm_clips", "rotation", "schedule",
               "step_size", "step_gamma", "jitter_px", "marker_dropout", "displacement_scale", "patience",
               "select_metric", "calibration", "remove_common_motion", "align", "align_stats", "select_on")


def job_from_config(cfg: DictConfig) -> TrainJob:
    """Plain dataclasses from the composed config (the only place that reads the DictConfig)."""
    c = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)  # the choice keys' enums as their strings
    c.pop("hydra", None)
    train = TrainConfig(**{k: c["recipe"][k] for k in RECIPE_KEYS}, **c["train"], device=c["device"])
    return TrainJob(config_name=c["config_name"], seed=int(c["seed"]), clip_len=int(c["clip_len"]),
                    train_on=c["train_on"], test_on=c["test_on"], data=c["data"],
                    model=ModelConfig(**c["model"]), train=train, rest=c["graph"]["rest"])


def _overrides() -> dict:
    try:
        return {"overrides": " ".join(HydraConfig.get().overrides.task)[:5000]}
    except ValueError:  # not inside a Hydra job (tests)
        return {}


def also_tested(cfg: DictConfig, job, out_dir) -> list[tuple[str, str, Path]]:
    """(config name, test set, run dir) of every `also_test` entry "<name>:<test set>": the run dir
    <root>/<name>/L<n> beside this one, <root>/<config_name>/L<n> (with `seeds`), or <root>/<name>/L<n>/seed<s>
    beside <root>/<config_name>/L<n>/seed<s> (one seed), so each keeps the workflow's run layout."""
    if not cfg.also_test:
        return []
    out_dir, seed_dir = Path(out_dir), ""
    if cfg.seeds is None:
        out_dir, seed_dir = out_dir.parent, out_dir.name
    if out_dir.name != f"L{job.clip_len}" or out_dir.parent.name != job.config_name \
            or seed_dir not in ("", f"seed{job.seed}"):
        where = f"<root>/{job.config_name}/L{job.clip_len}" + ("" if cfg.seeds is not None else f"/seed{job.seed}")
        raise ValueError(f"also_test needs the run dir {where} (got {Path(out_dir) / seed_dir}): "
                         "set hydra.run.dir so the other configurations' folders sit beside it")
    pairs = [str(entry).partition(":") for entry in cfg.also_test]
    names = [name for name, _, _ in pairs]
    bad = [f"{n}{c}{t}" for n, c, t in pairs if not c or not n or t not in cfg.data]
    if bad or job.config_name in names or len(set(names)) != len(names):
        raise ValueError(f"also_test={list(cfg.also_test)}: list distinct '<config name>:<test set>' entries, test "
                         f"sets among {sorted(cfg.data)}, names other than config_name ({job.config_name})")
    return [(name, test_on, out_dir.parents[1] / name / out_dir.name / seed_dir) for name, _, test_on in pairs]


def run(cfg: DictConfig, out_dir: str | Path | None = None) -> dict | list[dict]:
    """The job body; `out_dir` defaults to Hydra's output dir. With `seeds`, one metrics dict per seed."""
    if out_dir is None:
        out_dir = HydraConfig.get().runtime.output_dir
    job = job_from_config(cfg)
    job = replace(job, train=replace(job.train, device=shared_cuda(job.train.device)))  # a free card of several
    params = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
    params.pop("hydra", None)
    params["recipe"].pop("sizes", None)  # the chosen sizes are in train.*
    tags = {**_overrides(), "recipe": str(cfg.recipe.name)}  # MLflow tags only; outputs do not carry them
    if cfg.seeds is not None:
        seeds = [int(s) for s in cfg.seeds]
        if not seeds or len(set(seeds)) != len(seeds):
            raise ValueError(f"seeds={seeds}: list distinct seeds, at least one (or seeds=null to train `seed` alone)")
        tests = [(job.config_name, job.test_on, Path(out_dir))] + also_tested(cfg, job, out_dir)
        jobs = [replace(job, seed=s, config_name=name, test_on=test_on) for name, test_on, _ in tests for s in seeds]
        dirs = [d / f"seed{s}" for *_, d in tests for s in seeds]
        per_job = [{**params, "seed": s, "config_name": name, "test_on": test_on} for name, test_on, _ in tests
                   for s in seeds]
        if cfg.also_uncalibrated:  # the same models' raw scores: the ablation's robust minus `calibration`
            if job.train.calibration == "none":
                raise ValueError(f"also_uncalibrated={cfg.also_uncalibrated}: recipe {cfg.recipe.name} calibrates "
                                 "nothing; drop also_uncalibrated")
            root = Path(cfg.also_uncalibrated)
            dirs += [root / j.config_name / f"L{j.clip_len}" / f"seed{j.seed}" for j in jobs]
            per_job += [{**p, "recipe": {**p["recipe"], "calibration": "none"}} for p in per_job]
            jobs += [replace(j, train=replace(j.train, calibration="none")) for j in jobs]
        return run_jobs_together(jobs, dirs, params=per_job, track=bool(cfg.track), tags=tags,
                                 progress=bool(cfg.progress))
    if cfg.also_uncalibrated:
        raise ValueError("also_uncalibrated uses the models of `seeds` trained together: pass seeds=[...]")
    also = [(replace(job, config_name=name, test_on=test_on), d, {**params, "config_name": name, "test_on": test_on})
            for name, test_on, d in also_tested(cfg, job, out_dir)]
    return run_job(job, out_dir, params=params, track=bool(cfg.track), tags=tags,
                   progress=bool(cfg.progress), also=also)


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="train")
@app_main("train")
def main(cfg: DictConfig) -> float:
    metrics = run(cfg)
    if isinstance(metrics, list):  # seeds trained together or also_test: the mean over this configuration's seeds
        own = [m["test"]["ap"] for m in metrics if m["config"] == cfg.config_name]
        return sum(own) / len(own)
    return metrics["test"]["ap"]  # for sweepers that optimise


if __name__ == "__main__":
    main()
