"""Hydra entry point: the downstream judge of the candidate twins (docs/slides.md "Twin on the task").

task=fold_twin -> `out.fit`: the slide loop's `fold` twin as a twin option (twin_fit/fitted.yaml), from
                 `slide_loop` (slide_loop.json); a Sim set is simulated with it like with any fitted twin.
task=slides    -> `out.json` + `out.npz`: the composed twin (twin=..., +twin_fit=...) replayed along the
                 Silicone slides of the slide loop's cut it never saw (all of them, or the other fold's
                 with `fold`): per-trial motion MAE px and over-/off-vessel ratios, sim markers.
task=choice    -> `out.choice` (choice.json: candidates, MAEs, p, chosen, why) + `out.choice_fit`: the main Sim set's
                 twin (dataset_twin: auto = the evidence's choice by the held-out slide MAE, or a pinned candidate),
                 from the replays alone (report.twin_selection.sim_set_choice, the table's own choice function).
task=table     -> `out.csv` + `out.md` (report.twin_selection: one row per candidate, `chosen` by the held-out
                 slide MAE with the tie rule: simplest first), `out.figure` (.png/.pdf: real vs the chosen twin's motion over one trial),
                 `out.bounds` (drift_bounds.csv: the held-out MAE that predictors without a twin reach, slides.diagnosis).
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from palpation.apps.slide_loop import select
from palpation.config_check import app_main
from palpation.config_ranges import SEEDS, Choice, DictOf, Int, ListOf
from palpation.io import csv_text, save_json, save_npz, save_text
from palpation.measured_sequences import load_sequence_set
from palpation.metrics.scores import load_scores
from palpation.readers import read_json, read_npz, read_text
from palpation.report.markdown import markdown
from palpation.report.runs import run_dir
from palpation.report.twin_selection import (COLUMNS, DATASET_TWINS, Candidate, Member, rule_text, selection_table,
                                             sim_set_choice)
from palpation.slides.diagnosis import BOUNDS_COLUMNS, drift_bounds
from palpation.slides.folds import FOLDS, trial_folds
from palpation.slides.twins import (heldout_trials, read_slide_loop, scene_params, schedule_of, score,
                                        write_fold_twin)

log = logging.getLogger(__name__)


def fold_twin(cfg: DictConfig) -> dict:
    loop = read_slide_loop(cfg.slide_loop)
    over = write_fold_twin(loop, str(cfg.fold), cfg.out.fit, str(cfg.slide_loop))
    log.info("fold %s twin: %s -> %s", cfg.fold, over, cfg.out.fit)
    return over


def slides(cfg: DictConfig) -> dict:
    from palpation.slides.replay import make_scene, replay
    from palpation.twin.markers import bind_markers
    from palpation.twin.mesh import SensorMesh, cached_sensor_mesh

    twin = OmegaConf.to_object(cfg.twin)
    loop = read_slide_loop(cfg.slide_loop)
    scored, fitted = heldout_trials(loop, cfg.fold)
    sset = load_sequence_set(cfg.sequences)
    sub, _ = select(sset, scored, loop["size"]["frames"])
    mesh = SensorMesh.load(cfg.mesh) if cfg.mesh else cached_sensor_mesh(twin.mesh.resolution)
    binding = bind_markers(mesh.nodes, mesh.dome_nodes, sset.rest)
    lead_in = float(loop.get("replay", {}).get("lead_in_mm", 0.0))  # as the slide loop replayed (0: older json)
    # each trial in the real scene as fitted by the fold that never saw it (its phantom slope), for every candidate
    groups: dict[str, list[int]] = {}
    for i, t in enumerate(scored):
        groups.setdefault(next(f for f in loop["folds"] if t not in loop["folds"][f]), []).append(i)
    markers = np.full((len(scored), sub.n_frames, len(sset.rest), 2), np.nan)
    failed = np.zeros(len(scored), bool)
    for f, idx in groups.items():
        m, fl = replay(mesh, twin, binding, sub.subset(idx), make_scene(sset),
                       [{**schedule_of(twin), **scene_params(loop, f)}], device=twin.device, lead_in_mm=lead_in)
        markers[idx], failed[idx] = m[0], fl[0]
    out = {"twin": cfg.name, "fold": cfg.fold, "trials": scored, "fitted_trials": fitted,
           "frames": loop["size"]["frames"], "scene": {f: scene_params(loop, f) for f in groups},
           **score(markers, failed, sub)}
    out["heldout_slide_mae_px"] = float(np.mean(out["mae_px"]))
    save_json(cfg.out.json, out)
    save_npz(cfg.out.npz, markers=markers.astype(np.float32), trials=np.array(scored))
    log.info("twin %s on Silicone trials %s: motion MAE %.3f px, vessel ratio sim %.3f / real %.3f",
             cfg.name, scored, out["heldout_slide_mae_px"], out["vessel_ratio_sim"], out["vessel_ratio_real"])
    return out


def _member(c: dict, name: str, fold: str | None, n_trials: int) -> Member:
    """A fold twin stands for its whole parity class of the Silicone trials (slides.folds), also those outside
    the slide loop's cut, so that the cross-fitted pool covers every trial, as at the paper size."""
    root = Path(c["runs"][name if fold is None else f"{name}_{fold}"])
    scores = {exp: {s: load_scores(run_dir(root, c["experiments"][exp], c["clip_len"], s) / "scores.npz")
                    for s in c["seeds"]} for exp in ("silicone", "meat")}
    own = [] if fold is None else [t + 1 for t in trial_folds(list(range(1, n_trials + 1)))[fold]]
    return Member(own, scores["silicone"], scores["meat"])


def _candidates(c: dict, with_runs: bool = True) -> tuple[list[Candidate], dict]:
    """The candidates (conf order: simplest first) from their replays; their models' scores `with_runs`."""
    candidates, replays = [], {}
    n_trials = load_sequence_set(c["sequences"]).n_trials if with_runs else 0
    for name, spec in c["candidates"].items():
        folds = spec.get("folds") or [None]
        reps = [read_json(c["slides"][name if f is None else f"{name}_{f}"], "rerun rule judge_slides")
                for f in folds]
        replays[name] = reps
        trials = [t for r in reps for t in r["trials"]]
        mae = [m for r in reps for m in r["mae_px"]]
        candidates.append(Candidate(
            twin=name, fitted_on=spec["fitted_on"],
            members=[_member(c, name, f, n_trials) for f in folds] if with_runs else [],
            heldout_slide_mae_px=float(np.mean(mae)) if mae else float("nan"),
            vessel_ratio_sim=float(np.mean([r["vessel_ratio_sim"] for r in reps])),
            vessel_ratio_real=float(np.mean([r["vessel_ratio_real"] for r in reps])),
            trial_mae_px={int(t): float(m) for t, m in zip(trials, mae)}))
        log.info("%s: held-out slide motion MAE %.3f px over trials %s", name, candidates[-1].heldout_slide_mae_px,
                 sorted(trials))
    return candidates, replays


def choice(cfg: DictConfig) -> dict:
    """The main Sim set's twin (rule twin_choice): `out.choice` (choice.json) and the twin's fitted.yaml copied to
    `out.choice_fit`. Reads the held-out replays only, so it runs before (and without) any training."""
    c = OmegaConf.to_container(cfg, resolve=True)
    candidates, _ = _candidates(c, with_runs=False)
    rec = sim_set_choice(candidates, str(c["dataset_twin"]))
    folds = c["candidates"][rec["sim_set_twin"]].get("folds")
    # a slide-loop row is two fold twins; one Sim set takes the first fold's (it saw that fold's Silicone trials)
    source = rec["sim_set_twin"] if not folds else f"{rec['sim_set_twin']}_{folds[0]}"
    if source not in c["fits"]:
        raise ValueError(f"twin_judge task=choice: no fitted twin for {source!r} under `fits` "
                         f"(has {sorted(c['fits'])}); pass fits.{source}=<dir>/twin_fit/fitted.yaml")
    rec["fit"] = str(c["fits"][source])
    if folds:
        rec["note"] = (f"fold {folds[0]}'s twin, fitted on that fold's Silicone trials: the main tables' Silicone "
                       "scores are then not cross-fitted for them (the judge's table is)")
    text = read_text(rec["fit"], f"pass fits.{source}=<dir>/twin_fit/fitted.yaml of a finished run", "fitted twin")
    head, _, body = text.partition("\n")
    if not head.startswith("# @package"):
        raise ValueError(f"{rec['fit']}: not a twin option (first line {head!r}, need '# @package twin'); "
                         "rerun the rule that writes it")
    save_text(c["out"]["choice_fit"], f"{head}\n# Main Sim set's twin ({rec['how']}), copied by twin_judge task=choice "
                                      f"from {rec['fit']}\n{body}")
    save_json(c["out"]["choice"], rec)
    log.info("main Sim set twin: %s (%s; %s) -> %s", rec["sim_set_twin"], rec["how"],
             next(r["why"] for r in rec["candidates"] if r["twin"] == rec["chosen"]), c["out"]["choice_fit"])
    return rec


def table(cfg: DictConfig) -> dict:
    c = OmegaConf.to_container(cfg, resolve=True)
    candidates, replays = _candidates(c)
    df = selection_table(candidates)  # candidates in conf order: simplest first (the tie rule's order)
    chosen = str(df.loc[df["chosen"], "twin"].iloc[0])
    made = read_json(c["choice"], "rerun rule twin_choice") if c.get("choice") else None
    if made and made["chosen"] != chosen:  # rule twin_choice's record: the same function, the same replays
        raise ValueError(f"{c['choice']} chose {made['chosen']} but the table chooses {chosen} from the same replays; "
                         "rerun rule twin_choice (its replays are older or newer than the table's)")
    save_text(c["out"]["csv"], csv_text(df.to_dict("records"), COLUMNS, 4, na_rep="nan"))
    rows = [[str(r[k]).replace("|", "/") if not isinstance(r[k], float) else f"{r[k]:.3f}" for k in COLUMNS]
            for r in df.to_dict("records")]
    note = f"Models: recipe {c['trained_with']}, every candidate alike.\n\n" if c.get("trained_with") else ""
    note += f"Choice, rows top to bottom: {rule_text()}; `why` gives each row's test.\n\n"
    if made:
        note += f"The main Sim set's twin: {made['sim_set_twin']} ({made['how']}; config dataset.twin).\n\n"
    save_text(c["out"]["md"], f"# Twin on the task ({c['profile']} profile)\n\n{note}" + markdown(list(COLUMNS), rows))
    sset = load_sequence_set(c["sequences"])  # read once for the figure and the bounds
    _figure(c, sset, chosen, replays[chosen])
    _bounds(c, sset, [r for reps in replays.values() for r in reps])
    log.info("twin selection: chosen %s -> %s", chosen, c["out"]["csv"])
    return {"chosen": chosen, "rows": df.to_dict("records")}


def _bounds(c: dict, sset, reps: list[dict]) -> None:
    """out.bounds: the held-out MAE of predictors that need no twin (slides.diagnosis.drift_bounds) on the
    replays' trials and frames, so the page can read the slide-loop aim against what is reachable at all."""
    trials = sorted({int(t) for r in reps for t in r["trials"]})
    sub, numbers = select(sset, trials, reps[0]["frames"])
    df = drift_bounds(sub, numbers)
    save_text(c["out"]["bounds"], csv_text(df.to_dict("records"), BOUNDS_COLUMNS, 4))
    log.info("drift bounds (held-out motion MAE px): %s -> %s",
             ", ".join(f"{r.predictor} {r.heldout_mae_px:.3f}" for r in df.itertuples()), c["out"]["bounds"])


def _figure(c: dict, sset, chosen: str, reps: list[dict]) -> None:
    from palpation.figures.slide_motion import slide_motion_figure

    trial = int(c["figure_trial"]) if c["figure_trial"] is not None else reps[0]["trials"][0]
    rep = next((r for r in reps if trial in r["trials"]), None)
    if rep is None:
        raise ValueError(f"figure_trial={trial}: the {chosen} twin's replays hold trials "
                         f"{[r['trials'] for r in reps]}; pick one of them")
    name = chosen if rep["fold"] is None else f"{chosen}_{rep['fold']}"
    sim = read_npz(Path(c["slides"][name]).with_suffix(".npz"), ("markers", "trials"), "rerun rule judge_slides")
    first, end = rep["frames"]
    i = list(sim["trials"]).index(trial)
    slide_motion_figure(sset.markers[trial - 1, first:end], sim["markers"][i], sset.labels[trial - 1, first:end],
                        c["out"]["figure"], f"Silicone trial {trial}, {chosen} twin")


TASKS = {"fold_twin": fold_twin, "slides": slides, "choice": choice, "table": table}
RANGES = {"task": Choice(*TASKS), "fold": Choice(*FOLDS, null=True), "candidates": DictOf(min_len=1),  # before any work
          "candidates.*.folds": ListOf(Choice(*FOLDS), unique=True), "dataset_twin": Choice(*DATASET_TWINS),
          "seeds": SEEDS, "clip_len": Int(ge=1), "figure_trial": Int(ge=1, null=True)}


def run(cfg: DictConfig) -> dict:
    if cfg.task not in TASKS:
        raise ValueError(f"unknown task '{cfg.task}' in conf/twin_judge.yaml: use one of {sorted(TASKS)}")
    return TASKS[cfg.task](cfg)


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="twin_judge")
@app_main("twin_judge", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
