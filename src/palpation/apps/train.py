"""Hydra entry point: train one ST-GNN configuration x seed and score it (SPEC §8-§11).

    python -m palpation.apps.train experiment=A-to-B seed=0
    python -m palpation.apps.train --multirun experiment=A-to-B seed=0,1,2,3,4
    python -m palpation.apps.train experiment=A-to-B 'seeds=[0,1,2,3,4]' device=cuda   # one process
    python -m palpation.apps.train experiment=A-to-B 'seeds=[0,1]' 'also_test=[A-to-C:meat]' \
        hydra.run.dir=results/adhoc/train/A-to-B/L5        # one training, scored on Silicone and Meat
    python -m palpation.apps.train experiment=A-to-A seed=0 'also_test=[A-to-B:silicone]' \
        hydra.run.dir=results/adhoc/train/A-to-A/L5/seed0  # the same with one seed (no stacking)
    ... recipe=robust also_uncalibrated=results/adhoc/uncalibrated   # and its raw scores written there too
    ... recipe=robust 'also_aligned=[coral:test_set:results/adhoc/coral]'   # and scored CORAL-aligned there
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
from palpation.graph.align import METHODS as ALIGN_METHODS, STATS_FROM as ALIGN_STATS
from palpation.model.gpu_slots import shared_cuda
from palpation.model.job import TrainJob, job_from_settings, run_job, run_jobs_together

log = logging.getLogger(__name__)


def job_from_config(cfg: DictConfig) -> TrainJob:
    """Plain dataclasses from the composed config (the only place that reads the DictConfig); enums as strings."""
    return job_from_settings(OmegaConf.to_container(cfg, resolve=True, enum_to_str=True))


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


def also_aligned(cfg: DictConfig) -> list[tuple[str, str, Path]]:
    """(align, align_stats, folder) of every `also_aligned` entry "<align>:<align_stats>:<folder>"; each differs
    from the recipe's own alignment and the folders are distinct."""
    out = []
    for entry in cfg.also_aligned:
        align, _, rest = str(entry).partition(":")
        stats, _, folder = rest.partition(":")
        if align not in ALIGN_METHODS[1:] or stats not in ALIGN_STATS or not folder:
            raise ValueError(f"also_aligned entry {entry!r}: write '<align>:<align_stats>:<folder>' with align in "
                             f"{list(ALIGN_METHODS[1:])} and align_stats in {list(ALIGN_STATS)}")
        out.append((align, stats, Path(folder)))
    if out and cfg.also_uncalibrated:
        raise ValueError("also_aligned and also_uncalibrated write one folder per run each: use one of them")
    own = (str(cfg.recipe.align), str(cfg.recipe.align_stats))
    if any((a, s) == own for a, s, _ in out) or len({f for *_, f in out}) != len(out):
        raise ValueError(f"also_aligned={list(cfg.also_aligned)}: list distinct folders, each with an alignment other "
                         f"than the recipe's own ({own[0]}:{own[1]})")
    return out


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
        base = list(zip(jobs, per_job))
        for align, stats, root in also_aligned(cfg):  # the same models, the scored clips aligned (docs/transfer.md)
            dirs += [root / j.config_name / f"L{j.clip_len}" / f"seed{j.seed}" for j, _ in base]
            per_job += [{**p, "recipe": {**p["recipe"], "align": align, "align_stats": stats}} for _, p in base]
            jobs += [replace(j, train=replace(j.train, align=align, align_stats=stats)) for j, _ in base]
        return run_jobs_together(jobs, dirs, params=per_job, track=bool(cfg.track), tags=tags,
                                 progress=bool(cfg.progress))
    for key in ("also_uncalibrated", "also_aligned"):
        if cfg[key]:
            raise ValueError(f"{key} uses the models of `seeds` trained together: pass seeds=[...]")
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
