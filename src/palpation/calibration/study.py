"""One calibration search: check the inputs, build the objective, run the persistent Optuna study.

Everything that can be wrong with the inputs (names, bounds, fixed values, missing photos, options)
is checked in `prepare` before the twin is built. The study is named after a hash of every setting
that changes what a trial means (objective, space, fixed values, twin physics, mesh, seeds), but not
after `n_trials`: asking for more trials extends the same study, a changed setting starts a new one
in the same SQLite file, and a killed run resumes where it stopped.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np
import optuna

from palpation.calibration.config import CalibrationConfig
from palpation.calibration.objective import PhotoObjective, photo_targets
from palpation.calibration.params import check_space, warn_inert
from palpation.calibration.reference import ReferenceObjective, heading_once
from palpation.calibration.search import TrialResult, completed, make_sampler, open_study, run_search
from palpation.measured import MeasuredSet
from palpation.progress import bar
from palpation.twin.config import TwinConfig
from palpation.twin.markers import MarkerBinding
from palpation.twin.mesh import SensorMesh
from palpation.twin.runner import simulate_states

log = logging.getLogger(__name__)
STUDY_DB = "study.db"


@dataclass
class Prepared:
    cfg: CalibrationConfig
    twin: TwinConfig
    targets: list  # the measured Target of every configured interaction (fit, held out, validated)

    def target(self, kind: str):
        return next(t for t in self.targets if t.kind == kind)


def prepare(cfg: CalibrationConfig, twin: TwinConfig, mset: MeasuredSet, source: str) -> Prepared:
    """All input checks; raises ValueError before anything is simulated."""
    cfg.validate()
    twin.validate()
    check_space(cfg.space(), cfg.fixed)
    if cfg.objective == "reference" and "slide" not in cfg.interactions:
        raise ValueError("calibration.objective=reference scores the slide photo: keep 'slide' in "
                         f"calibration.interactions (got {list(cfg.interactions)})")
    targets = photo_targets(mset, cfg.interactions, source)
    warn_inert(cfg.space(), vessel=cfg.objective == "reference", cfg=twin, where="calibration.params")
    return Prepared(cfg, twin, targets)


def study_key(cfg: CalibrationConfig, twin: TwinConfig, resolution: str) -> str:
    """A study name from every setting that changes a trial's value (not n_trials)."""
    keep = {k: v for k, v in dataclasses.asdict(cfg).items() if k not in ("n_trials", "paper")}
    physics = {k: v for k, v in dataclasses.asdict(twin).items() if k not in ("device",)}
    blob = json.dumps({"cfg": keep, "twin": physics, "mesh": resolution}, sort_keys=True, default=str)
    return f"{cfg.objective}-{hashlib.sha1(blob.encode()).hexdigest()[:10]}"


def build_objective(prep: Prepared, mesh: SensorMesh, binding: MarkerBinding, device: str):
    """The configured objective, with `.direction` and `.evaluate(proposals) -> [TrialResult]`."""
    cfg, twin = prep.cfg, prep.twin
    if cfg.objective == "reference":
        return ReferenceObjective(mesh, twin, prep.target("slide").markers, heading_once(cfg.heading_seed),
                                  fixed=cfg.fixed, binding=binding, device=device, trigger_px=cfg.trigger_px,
                                  cap_frames=cfg.cap_frames, norm_px=cfg.norm_px, worst=cfg.worst_value,
                                  max_frames=cfg.max_frames)
    simulate = partial(simulate_states, mesh, twin, device=device, binding=binding,
                       split_by_kind=cfg.split(device), max_frames=cfg.max_frames)
    return PhotoObjective(prep.targets, simulate, cfg.fit_interactions(), fixed=cfg.fixed,
                          worst_px=cfg.worst_px, geometry=cfg.geometry, twist_z_angle=cfg.twist_z_angle)


def run_study(prep: Prepared, mesh: SensorMesh, binding: MarkerBinding, out_dir: Path, device: str,
              on_trial: Callable[[optuna.trial.FrozenTrial, TrialResult], None] | None = None,
              progress: bool = True) -> optuna.Study:
    """Run (or resume) the search until the study holds `n_trials` completed trials."""
    cfg = prep.cfg
    objective = build_objective(prep, mesh, binding, device)
    name = study_key(cfg, prep.twin, mesh.resolution)
    study = open_study(Path(out_dir) / STUDY_DB, name, make_sampler(cfg.sampler, cfg.seed, cfg.n_startup),
                       objective.direction)
    done = completed(study)
    log.info("study '%s' in %s: %d of %d trials done", name, Path(out_dir) / STUDY_DB, done, cfg.n_trials)

    seen = {_key(t.params): TrialResult(t.value, bool(t.user_attrs.get("diverged", False)),
                                        {k: v for k, v in t.user_attrs.items() if k != "diverged"})
            for t in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))}

    def timed(proposals):
        # a GP often re-proposes a bound it is stuck on: the twin is deterministic, so an exact repeat
        # reuses the earlier result ("cached" = 1) instead of simulating it again
        fresh = list(dict.fromkeys(k for k in map(_key, proposals) if k not in seen))
        if fresh:
            start = time.perf_counter()
            results = objective.evaluate([dict(k) for k in fresh])
            wall = time.perf_counter() - start
            for k, r in zip(fresh, results):
                seen[k] = TrialResult(r.value, r.diverged, {**r.metrics, "wall_s/batch": wall,
                                                            "batch_size": float(len(fresh)), "cached": 0.0})
        out = []
        for k in map(_key, proposals):
            metrics = {**seen[k].metrics, "cached": float(k not in fresh)}
            out.append(TrialResult(seen[k].value, seen[k].diverged, metrics))
        return out

    with bar(total=cfg.n_trials, initial=min(done, cfg.n_trials), desc="calibrate", unit="trial",
             enabled=progress) as trials:
        run_search(study, cfg.space(), cfg.n_trials, cfg.n_startup, cfg.batch_size, timed,
                   on_trial=on_trial, progress=trials.update)
    return study


def _key(params: dict) -> tuple:
    return tuple(sorted((k, float(v)) for k, v in params.items()))


def at_bounds(params: dict, space: list, tol: float = 0.01) -> list[str]:
    """Searched names whose fitted value lies within `tol` of a bound (in log space where searched so)."""
    out = []
    for p in space:
        f = np.log if p.log else (lambda x: x)
        u = (f(params[p.name]) - f(p.low)) / (f(p.high) - f(p.low))
        if u < tol or u > 1 - tol:
            out.append(p.name)
    return out


def best_trial(study: optuna.Study) -> optuna.trial.FrozenTrial:
    """The best completed trial that did not diverge (a diverged one only carries the worst value)."""
    ok = [t for t in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
          if not t.user_attrs.get("diverged", False)]
    if not ok:
        raise ValueError(f"study '{study.study_name}': every trial diverged; narrow the bounds (a too large "
                         "k_n or a too soft E are the usual causes, SPEC §2.4)")
    sign = -1.0 if study.direction == optuna.study.StudyDirection.MAXIMIZE else 1.0
    return min(ok, key=lambda t: (sign * t.value, t.number))


def trial_rows(study: optuna.Study) -> list[dict]:
    """One plain row per trial (number, state, value, params, metrics) for trials.csv and the plot."""
    rows = []
    for t in study.get_trials(deepcopy=False):
        rows.append({"trial": t.number, "state": t.state.name,
                     "value": float("nan") if t.value is None else float(t.value),
                     **{f"param/{k}": v for k, v in t.params.items()},
                     **{k: (float(v) if isinstance(v, (bool, int, float, np.floating)) else v)
                        for k, v in t.user_attrs.items()}})
    return rows
