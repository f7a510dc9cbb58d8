"""The loop on one measured set: round 0 (the calibrated twin), then effects while held-out error falls."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
from pathlib import Path
from typing import Mapping

import numpy as np

from palpation.loop.attribution import attribute
from palpation.loop.config import LoopConfig
from palpation.loop.effects import EFFECTS
from palpation.loop.engine import MIN_RMS_PX, refit_dofs, run_rounds, signatures
from palpation.loop.inputs import load_targets, set_key
from palpation.loop.problem import Problem, evaluate, initial_params
from palpation.loop.recalibrate import recalibrate
from palpation.loop.refit import finish
from palpation.loop.unexplained import check_all, noise_estimate
from palpation.measured import MeasuredSet
from palpation.twin.config import TwinConfig

log = logging.getLogger(__name__)


def twin_key(cfg: TwinConfig, resolution: str) -> str:
    """Hash of the physics the loop runs (not the device): part of every study name."""
    physics = {k: v for k, v in dataclasses.asdict(cfg).items() if k != "device"}
    blob = json.dumps({"twin": physics, "mesh": resolution}, sort_keys=True, default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:10]


def base_params(cfg: TwinConfig) -> dict[str, float]:
    """The starting twin's values of the loop parameters that the config sets (E, alpha)."""
    return {"E": cfg.material.E, "alpha": cfg.damping.alpha}


def make_problem(mset: MeasuredSet, source: str, cfg: LoopConfig, base: Mapping[str, float], name: str = "real",
                 holdout=None, states=None, effects_on=(), candidates=None) -> Problem:
    """A problem from any measured set: its states are checked before anything is simulated."""
    targets = load_targets(mset, source, cfg.holdout if holdout is None else holdout,
                           cfg.states if states is None else states, cfg.twist_z_angle)
    searched = list(dict.fromkeys(cfg.method.recalibrate))
    for e in effects_on:
        searched += [n for n in EFFECTS[e].params if n not in searched]
    cands = [e for e in (cfg.effects if candidates is None else candidates) if e not in effects_on]
    return Problem(name=name, key=set_key(mset), targets=targets, params=initial_params(base),
                   searched=searched, effects=list(effects_on), candidates=cands)


def round_zero(problems: list[Problem], simulate, cfg: LoopConfig, db_path: Path, tkey: str,
               progress: bool = False) -> None:
    """Fit `round0_params` (the calibrated twin before any effect) and record round 0."""
    if cfg.method.calibrate_round0:
        searched = {p.name: p.searched for p in problems}
        for p in problems:
            p.searched = list(cfg.method.round0_params)
        fits = recalibrate(problems, simulate, cfg.search, db_path, "r0", tkey,
                           {p.name: [dict(p.params)] for p in problems}, progress=progress)
        for p in problems:
            p.params.update(fits[p.name]["params"])
        finish(cfg, problems, fits, simulate)  # the calibrated twin at its local optimum (loop.polish)
        for p in problems:
            p.searched = searched[p.name]
    evaluate(problems, simulate)
    for p in problems:
        p.rounds.append({"round": 0, "effect": None, "accepted": True, "share_explained": 0.0, "ranking": [],
                         "best_subset": [], "best_subset_share": 0.0, "before": None, "params_before": None,
                         "markers_before": None, "after": p.summary(), "params_after": dict(p.params),
                         "markers_after": p.markers.copy()})


def reference_attribution(p: Problem, simulate, cfg: LoopConfig) -> dict:
    """Compensation guard: the attribution on the starting (reference-parameter) twin's residual, before
    round 0 recalibrates E, so an effect whose signature the stiffness absorbs there still shows."""
    evaluate([p], simulate)
    p.refit = refit_dofs(p)
    sigs, _, _ = signatures([p], simulate, dict(cfg.method.steps))
    fit_ix = [i for i, t in enumerate(p.targets) if t.fit]
    att = attribute(np.stack([p.markers[i] - p.targets[i].markers for i in fit_ix]), sigs[p.name],
                    min_rms_px=MIN_RMS_PX)
    p.markers = None  # round 0 evaluates its own twin
    return {"ranking": att.ranking, "best_subset": att.best_subset, "best_subset_share": att.best_subset_share}


def run_loop(mset: MeasuredSet, source: str, cfg: LoopConfig, simulate, base: Mapping[str, float],
             db_path: Path, tkey: str, on_round=None, progress: bool = False, effects_on=()) -> Problem:
    """Round 0, then up to cfg.max_rounds effects; returns the problem with its round records.
    `base`/`effects_on`: the starting twin (loop.start.start_twin); `progress`: tqdm bars over the
    rounds and each recalibration's trials."""
    cfg.validate()
    p = make_problem(mset, source, cfg, base, effects_on=effects_on)
    log.info("loop on %s: fit %s, held out %s, candidates %s", source, [t.name for t in p.targets if t.fit],
             [t.name for t in p.targets if not t.fit], p.candidates)
    p.reference_attribution = reference_attribution(p, simulate, cfg)
    round_zero([p], simulate, cfg, db_path, tkey, progress)
    if on_round is not None:
        on_round(0, [p])
    sigma, where = noise_estimate(mset, cfg.noise_px)
    p.noise_px = sigma  # a set at this noise level leaves nothing for a larger effect set (loop.compete)
    run_rounds([p], simulate, cfg, db_path, tkey, cfg.max_rounds, on_round, progress)
    check_all([p], simulate, cfg, {p.name: sigma})
    p.final["noise_source"] = where
    return p
