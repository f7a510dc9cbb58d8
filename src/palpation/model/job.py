"""One training job end to end: load data, fit, score the test set, write outputs, track the run.

Outputs in `out_dir`: checkpoint.pt (weights + normalisation statistics + rest layout), scores.npz
(`probs`, `labels` of the test central frames, their `sequence`, `frame` ids: palpation.metrics.scores),
pr.npz (the test PR curve) and metrics.json. `run_jobs_together` does the same for several seeds of one
configuration trained in one process (palpation.model.stacked), one output folder and MLflow run per seed, and
can score the same models on several test sets (configurations that train alike share the training).
"""

from __future__ import annotations

import logging
import platform
import time
from contextlib import nullcontext
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

from palpation import tracking
from palpation.graph.align import clip_moments
from palpation.graph.clips import ClipSet
from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.layout import rest_layout
from palpation.graph.sources import load_dataset
from palpation.io import save_json, save_npz
from palpation.metrics.aggregate import pr_curve
from palpation.metrics.calibration import ece, fit_calibrator, positive_share
from palpation.metrics.classification import marker_metrics
from palpation.metrics.scores import Scores, save_scores
from palpation.model.checkpoint import checkpoint_bytes, save_checkpoint
from palpation.model.config import ModelConfig, TrainConfig
from palpation.model.domain import (alignment, check_selection, is_partner, selection_name,
                                    selection_sequences)
from palpation.model.evaluate import predict
from palpation.model.stgnn import count_parameters
from palpation.model.restarts import fit_restarts, fit_seeds_restarts
from palpation.model.stacked import predict_seeds
from palpation.model.train import FitResult
from palpation.model.self_training import with_pseudo_clips

log = logging.getLogger(__name__)
OUTPUTS = ("metrics.json", "scores.npz", "pr.npz", "checkpoint.pt")
# the conf/recipe/ keys, which land in TrainConfig beside conf/train.yaml's `train:` section
RECIPE_KEYS = ("lr", "weight_decay", "focal_gamma", "norm_stats", "norm_clips", "rotation", "schedule",
               "step_size", "step_gamma", "jitter_px", "marker_dropout", "displacement_scale", "patience",
               "select_metric", "calibration", "remove_common_motion", "align", "align_stats", "select_on",
               "pseudo", "pseudo_from", "pseudo_min_agree", "pseudo_margin", "pseudo_weight")

# the pseudo-labelled set depends on the scored set (the other real one, or its own), so no training serves two
PSEUDO_APART = ("{}: recipe.pseudo self-trains on clips chosen by the scored set; train each configuration apart "
                "(drop also_test)")


@dataclass(frozen=True)
class TrainJob:
    config_name: str
    seed: int
    clip_len: int
    train_on: str
    test_on: str
    data: dict  # dataset name -> path
    model: ModelConfig
    train: TrainConfig
    rest: str = "template"


def job_from_settings(c: dict) -> TrainJob:
    """The job of the train app's composed config as plain containers (conf/train.yaml's keys, resolved)."""
    train = TrainConfig(**{k: c["recipe"][k] for k in RECIPE_KEYS}, **c["train"], device=c["device"])
    return TrainJob(config_name=c["config_name"], seed=int(c["seed"]), clip_len=int(c["clip_len"]),
                    train_on=c["train_on"], test_on=c["test_on"], data=c["data"],
                    model=ModelConfig(**c["model"]), train=train, rest=c["graph"]["rest"])


def device_name(device: str) -> str:
    if device.startswith("cuda") and torch.cuda.is_available():
        return torch.cuda.get_device_name(torch.device(device))
    return f"cpu ({platform.processor() or platform.machine()}, {torch.get_num_threads()} threads)"


@dataclass
class JobData:
    """The clip sets and graph structure of a job; seeds of one configuration share them."""

    rest: np.ndarray
    topo: object
    train: ClipSet
    val: ClipSet
    test: ClipSet
    pseudo: dict | None = None  # what the pseudo-labelled training clips were (recipe.pseudo), None when off


def load_job_data(job: TrainJob) -> JobData:
    rest = rest_layout(job.rest)
    topo = clip_topology(spatial_edges(rest), job.clip_len)
    train = ClipSet(load_dataset(job.train_on, job.data[job.train_on], "train"), job.clip_len, rest)
    train, pseudo = with_pseudo_clips(job, train, rest)  # unchanged unless recipe.pseudo is on
    val = ClipSet(selection_sequences(job), job.clip_len, rest)  # the training domain's val split unless select_on
    test = load_test_set(job, rest)
    log.info("%s L=%d: %d train / %d val / %d test clips", job.config_name, job.clip_len, len(train), len(val),
             len(test))
    return JobData(rest, topo, train, val, test, pseudo)


def load_test_set(job: TrainJob, rest: np.ndarray) -> ClipSet:
    return ClipSet(load_dataset(job.test_on, job.data[job.test_on], "test"), job.clip_len, rest)


def training_key(job: TrainJob) -> TrainJob:
    """What fixes a job's training: everything but its seed, the test set it is scored on, the post-hoc
    calibration of its scores (fitted after training, on the val split) and the alignment of the scored clips
    (applied at scoring only: docs/transfer.md)."""
    return replace(job, seed=0, config_name="", test_on=job.train_on, data={job.train_on: job.data[job.train_on]},
                   train=replace(job.train, calibration="none", align="none", align_stats="other_real"))


def scoring_key(job: TrainJob) -> tuple[str, str, str, str]:
    """What fixes a job's test scores once its models are trained, calibration aside: (config, test set, align,
    align_stats); jobs trained together are scored once per key."""
    return job.config_name, job.test_on, job.train.align, job.train.align_stats


def selection_record(job: TrainJob) -> dict:
    """metrics.json's record of where the training's checkpoint was chosen (nothing for the val split): the set and,
    for a half, its trials (the other half may score the method). Jobs trained together carry the first job's."""
    if job.train.select_on == "val":
        return {}
    out = {"selected_on": selection_name(job)}
    if out["selected_on"].endswith(" half"):
        out["selected_trials"] = [str(t) for t in selection_sequences(job).ids]
    return out


def _run_tags(job: TrainJob, tags: dict | None) -> dict:
    return {"config": job.config_name, "seed": str(job.seed), "clip_len": str(job.clip_len),
            "model": job.model.name, "device": job.train.device, **(tags or {})}


def run_job(job: TrainJob, out_dir: str | Path, params: dict | None = None, track: bool = True,
            tags: dict | None = None, progress: bool = False, also: list[tuple] = ()) -> dict | list[dict]:
    """Train, score and write outputs; returns the metrics dict also saved as metrics.json.

    `progress`: tqdm bars over the training batches and the test scoring. `also`: (job, out_dir, params) of
    configurations that train alike (same seed; only the test set differs, e.g. A-to-B and A-to-C beside A-to-A):
    the one model is scored on each test set, each with its own outputs and MLflow run, byte for byte what its
    own training would give (training reads no test set); then one metrics dict per configuration, `job` first,
    each with `trained_together` (its configs, the training wall seconds) and `train_seconds` its share."""
    if job.train.calibration == "cross_real":
        raise ValueError(f"{job.config_name}: calibration=cross_real fits on the same models' scores on another real "
                         "set; train with seeds=[...] and also_test=[<config>:<set>] (e.g. A-to-B with "
                         "also_test=[A-to-C:meat]), or use calibration=platt")
    others = list(also)
    if [o for o, *_ in others if not is_partner(o.config_name)] and job.train.pseudo != "none":
        raise ValueError(PSEUDO_APART.format(job.config_name))
    if any(training_key(o) != training_key(job) or o.seed != job.seed or o.train != job.train for o, *_ in others):
        raise ValueError(f"also: configurations scored by {job.config_name}'s model must train alike (same seed, "
                         "training set, model and recipe); train the others apart")
    check_selection([job] + [o for o, *_ in others])
    d = load_job_data(job)
    steps = []

    def log_and_keep(metrics, step):  # the other configurations' runs get the same history afterwards
        steps.append((dict(metrics), step))
        tracking.log_metrics(metrics, step)

    ctx = (tracking.start_run("train", params or asdict(job), f"{job.config_name}/L{job.clip_len}",
                              _run_tags(job, tags), seed=job.seed) if track else nullcontext())
    with ctx:
        result, restarts = fit_restarts(d.train, d.val, d.rest, d.topo, job.model, job.train, job.seed,
                                        (log_and_keep if others else tracking.log_metrics) if track else None,
                                        progress=progress)
        if not others:
            return finish_job(job, result, d, out_dir, track, progress, restarts)
        shared = {**restarts, **selection_record(job), "trained_together": {
            "seeds": [job.seed], "train_seconds": result.train_seconds,
            "configs": [job.config_name] + [o.config_name for o, *_ in others]}}
        share = replace(result, train_seconds=result.train_seconds / (1 + len(others)))
        out = [finish_job(job, share, d, out_dir, track, progress, shared)]
    for other, other_dir, other_params in others:
        ctx = (tracking.start_run("train", other_params or asdict(other), f"{other.config_name}/L{other.clip_len}",
                                  {**_run_tags(other, tags), "trained_with": job.config_name}, seed=other.seed)
               if track else nullcontext())
        with ctx:
            if track:
                tracking.log_metric_history(steps)
            test = d.test if (other.test_on, other.data) == (job.test_on, job.data) else load_test_set(other, d.rest)
            out.append(finish_job(other, share, replace(d, test=test), other_dir, track, progress, shared))
    return out


def run_jobs_together(jobs: list[TrainJob], out_dirs: list[str | Path], params: list[dict] | None = None,
                      track: bool = True, tags: dict | None = None, progress: bool = False) -> list[dict]:
    """`run_job` for seeds of one configuration (jobs differing only in seed) trained together
    (palpation.model.stacked); one MLflow run and one output folder per job, as separate jobs.

    Jobs may also differ in the test set they are scored on (`config_name`, `test_on`), in the post-hoc
    calibration of the scores (`train.calibration`) and in the alignment of the scored clips (`train.align`,
    `train.align_stats`): configurations that train alike (A-to-B and A-to-C both train the large model on Sim)
    then share one training, each seed's models scored on every test set under every alignment and written once
    per calibration; every seed must come with every (test set, alignment, calibration).

    Each test set is scored by all seeds at once (`predict_seeds`). metrics.json gains `trained_together`
    (the seeds and the joint training wall seconds; with several test sets also their `configs`);
    `train_seconds` and `test_seconds` are each job's share of the joint times."""
    first = jobs[0]
    if any(training_key(j) != training_key(first) for j in jobs):
        raise ValueError("jobs trained together must differ only in their seed, test set, alignment and calibration "
                         f"({first.config_name}, L={first.clip_len}); train other configurations apart")
    seeds = list(dict.fromkeys(j.seed for j in jobs))
    tests = list(dict.fromkeys((j.config_name, j.test_on) for j in jobs))
    scorings = list(dict.fromkeys(scoring_key(j) for j in jobs))
    outputs = list(dict.fromkeys((*scoring_key(j), j.train.calibration) for j in jobs))
    keys = [(*scoring_key(j), j.train.calibration, j.seed) for j in jobs]
    if len(set(keys)) != len(jobs) or len(jobs) != len(seeds) * len(outputs):
        raise ValueError(f"jobs trained together need every seed {seeds} once with every (test set, alignment, "
                         f"calibration) {outputs}")
    if len([t for t in tests if not is_partner(t[0])]) > 1 and first.train.pseudo != "none":
        raise ValueError(PSEUDO_APART.format(first.config_name))
    partner = {j.config_name: cross_real_partner(j, tests) for j in jobs if j.train.calibration == "cross_real"}
    check_selection(jobs)
    chosen_on = selection_record(first)
    d = load_job_data(first)
    results, restarts = fit_seeds_restarts(d.train, d.val, d.rest, d.topo, first.model, first.train, seeds,
                                           progress=progress)
    joint = results[0].train_seconds
    by_seed = dict(zip(seeds, results))
    together = {"seeds": seeds, "train_seconds": joint}
    if len(tests) > 1:
        together["configs"] = [name for name, _ in tests]
    scored, test_sets, aligned = {}, {}, {}
    source = clip_moments(d.train, d.rest, d.topo, first.train.remove_common_motion) \
        if any(j.train.align != "none" for j in jobs) else None
    for key in scorings:  # each test set scored by all seeds at once, per alignment; each job's share of the time
        job = next(j for j in jobs if scoring_key(j) == key)
        name = job.config_name
        if name not in test_sets:
            test_sets[name] = d.test if job.test_on == first.test_on and job.data == first.data \
                else load_test_set(job, d.rest)
        t0 = time.perf_counter()
        align = alignment(job, d.train, test_sets[name], d.rest, d.topo, source)
        aligned[key] = {"alignment": align.to_dict()} if align else {}
        per_seed = predict_seeds([r.model for r in results], [r.stats for r in results], test_sets[name], d.rest,
                                 d.topo, first.train.batch_size, first.train.device, progress, align)
        share = (time.perf_counter() - t0) / len(seeds)
        scored.update({(key, s): (*p, share) for s, p in zip(seeds, per_seed)})
    out = []
    for i, (job, out_dir) in enumerate(zip(jobs, out_dirs)):
        result = replace(by_seed[job.seed], train_seconds=joint / len(jobs))
        ctx = (tracking.start_run("train", params[i] if params else asdict(job),
                                  f"{job.config_name}/L{job.clip_len}",
                                  {**_run_tags(job, tags), "trained_together": ",".join(map(str, seeds))},
                                  seed=job.seed) if track else nullcontext())
        with ctx:
            if track:
                tracking.log_metric_history(result.steps)
            fit_on, key = None, scoring_key(job)
            if job.config_name in partner:  # the same seed's models' raw scores on the other real set, aligned alike
                other = next(k for k in scorings if k[0] == partner[job.config_name] and k[2:] == key[2:])
                fit_on = (*scored[(other, job.seed)][:2], partner[job.config_name])
            out.append(finish_job(job, result, replace(d, test=test_sets[job.config_name]), out_dir, track,
                                  progress, {**restarts[job.seed], **chosen_on, "trained_together": together,
                                             **aligned[key]},
                                  scored[(key, job.seed)], fit_on))
    return out


def cross_real_partner(job: TrainJob, tests: list[tuple[str, str]]) -> str:
    """The configuration whose test scores calibrate `job` under calibration=cross_real: the one other real test set
    (not Sim, not the job's own) among those scored by the same models."""
    others = [name for name, test_on in tests if test_on not in ("sim", job.test_on)]
    if len(others) != 1:
        raise ValueError(f"{job.config_name}: calibration=cross_real needs exactly one other real test set scored by "
                         f"the same models (also_test=[<config>:<set>]), got {others or 'none'} from {tests}")
    return others[0]


def finish_job(job: TrainJob, result: FitResult, d: JobData, out_dir: str | Path, track: bool,
               progress: bool = False, extra: dict | None = None, scored: tuple | None = None,
               fit_on: tuple | None = None) -> dict:
    """Score the test set with a fitted model (unless `scored`: its probs, labels and seconds), write the
    outputs, log them to the active run. `fit_on` (probs, labels, config name): the other real set's scores
    that calibration=cross_real is fitted on."""
    out_dir = Path(out_dir)
    rest, topo, val, test = d.rest, d.topo, d.val, d.test
    transfer = {} if "selected_on" in (extra or {}) else selection_record(job)  # trained together: the first's
    if scored is None:
        t0 = time.perf_counter()
        align = alignment(job, d.train, test, rest, topo)
        probs, labels = predict(result.model, test, result.stats, rest, topo, job.train.batch_size,
                                device=job.train.device, progress=progress, align=align)
        scored = (probs, labels, time.perf_counter() - t0)
        transfer.update({"alignment": align.to_dict()} if align else {})
    probs, labels, test_seconds = scored
    calibration, cal, fitted_on = {}, None, f"{job.train_on} val"
    if job.train.calibration == "cross_real":  # on the other real set's scores, never on this test set
        if fit_on is None:
            raise ValueError(f"{job.config_name}: calibration=cross_real needs the other real set's scores; train "
                             "with seeds=[...] and also_test=[<config>:<set>]")
        cal, fitted_on = fit_calibrator(fit_on[0], fit_on[1], "platt"), fit_on[2]
        calibration["calibration_fitted_on"] = fitted_on
    elif job.train.calibration != "none":  # fitted on the training domain's val split, never on test
        val_probs, val_labels = result.val_scores or predict(result.model, val, result.stats, rest, topo,
                                                             job.train.batch_size, job.train.val_batches,
                                                             job.train.device)
        cal = fit_calibrator(val_probs, val_labels, job.train.calibration)
    if cal is not None:
        raw = probs
        probs = cal.apply(raw)
        calibration.update({"calibration": cal.to_dict(), "test_raw": marker_metrics(raw, labels, job.train.threshold),
                            "ece_raw": ece(raw, labels), "pos_share_05_raw": positive_share(raw)})
        log.info("calibration %s on %d scores (%s): scale %.4f shift %.4f", cal.method, cal.n_fit, fitted_on,
                 cal.scale, cal.shift)
    test_metrics = marker_metrics(probs, labels, job.train.threshold)
    metrics = {
        "config": job.config_name, "seed": job.seed, "clip_len": job.clip_len,
        "model": job.model.name, "train_on": job.train_on, "test_on": job.test_on,
        "test": test_metrics, "best_epoch": result.best_epoch,
        "val_fg_iou": result.history[result.best_epoch]["val/fg_iou"], "history": result.history,
        "n_clips": {"train": len(d.train), "val": len(val), "test": len(test)},
        "alpha": result.stats.alpha, "n_parameters": count_parameters(result.model),
        "checkpoint_bytes": checkpoint_bytes(result.model),
        "train_seconds": result.train_seconds, "test_seconds": test_seconds,
        "device": device_name(job.train.device),
        **calibration,  # only with a calibration: the reference recipe's metrics.json is unchanged
        **transfer,  # only with a transfer option (docs/transfer.md)
        **({"pseudo_labels": d.pseudo} if d.pseudo else {}),
        **(extra or {}),
    }
    save_scores(out_dir / "scores.npz", Scores(probs, labels, *test.central_frames()))
    save_npz(out_dir / "pr.npz", **pr_curve(probs, labels))
    save_checkpoint(out_dir / "checkpoint.pt", result.model, job.model, result.stats, rest,
                    extra={"config": job.config_name, "seed": job.seed, "train_on": job.train_on})
    save_json(out_dir / "metrics.json", metrics)
    if track:
        tracking.log_metrics({f"test/{k}": v for k, v in test_metrics.items() if np.isfinite(v)})
        tracking.log_metrics({"val/fg_iou_best": metrics["val_fg_iou"],
                              "time/train_s": result.train_seconds})
        for name in OUTPUTS:
            if name != "checkpoint.pt":
                tracking.log_artifact(out_dir / name)
        tracking.log_checkpoint(out_dir / "checkpoint.pt", {"model": job.model.name, "clip_len": job.clip_len,
                                                            "train_on": job.train_on, "seed": job.seed})
    log.info("test %s: AUROC %.4f AP %.4f FG %.4f BG %.4f", job.test_on, test_metrics["auroc"],
             test_metrics["ap"], test_metrics["fg_iou"], test_metrics["bg_iou"])
    return metrics
