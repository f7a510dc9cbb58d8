"""Recalibrate every problem's searched parameters with the calibration machinery, in lockstep.

Each problem (a measured set in a round) gets its own persistent Optuna study in one journal file,
named after a hash of everything that changes what a trial means (data, round, effects, space,
fixed values, sampler settings), so a killed run resumes and a changed setting starts afresh. The
studies advance together: each step asks every unfinished study for its next proposals and simulates
all of them as one twin batch (on a GPU, one run carries all self-test sets). The objective is the
mean marker MAE over the problem's fitted states; a diverged trial scores `worst_px`. Warm starts
(the current values, and the attribution's linear estimate) are enqueued as the first trials.
"""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
import optuna

from palpation.calibration.objective import marker_mae_px
from palpation.calibration.search import (ParamSpec, completed, make_sampler, next_batch, open_study,
                                          validate_space)
from palpation.loop.config import SearchSettings
from palpation.loop.effects import PARAMS, bounds, clip
from palpation.progress import bar

log = logging.getLogger(__name__)

# simulate(jobs) -> (markers (n, 127, 2), failed (n,)); a job is (State, params)
Simulate = Callable[[list], tuple[np.ndarray, np.ndarray]]


def space_of(names: Sequence[str], overrides: Mapping[str, Sequence[float]] | None = None) -> list[ParamSpec]:
    space = [ParamSpec(n, *bounds(n, overrides), PARAMS[n].log) for n in names]
    validate_space(space, known=set(PARAMS))
    return space


LOOP_STUDY = "study.journal"  # the loop's study file under out.dir (calibration.search.study_storage)

# bump when what a trial means changes in code (warm starts, objective): old studies are then not resumed
SEARCH_VERSION = 5  # 5: nested starts (loop.refit.subset_starts) among the warm starts


def study_name(key: str, tag: str, space: list[ParamSpec], fixed: Mapping[str, float], s: SearchSettings,
               twin_key: str) -> str:
    search = {k: v for k, v in s.__dict__.items() if k != "ask_workers"}  # where proposals are made: no matter
    blob = json.dumps({"version": SEARCH_VERSION, "key": key, "tag": tag, "space": [p.__dict__ for p in space],
                       "fixed": {k: float(v) for k, v in sorted(fixed.items())}, "search": search,
                       "twin": twin_key}, sort_keys=True, default=str)
    return f"loop-{tag}-{hashlib.sha1(blob.encode()).hexdigest()[:10]}"


def recalibrate(problems: list, simulate: Simulate, settings: SearchSettings, db_path: Path, tag: str,
                twin_key: str, warm: Mapping[str, list[dict]] | None = None,
                progress: bool = False) -> dict[str, dict]:
    """Search each problem's `searched` names; returns {problem name: {best params, value, trial, study}}.

    `problems` carry .name, .key, .params (all values), .searched, .fit_targets(); `warm` maps a
    problem name to proposals to enqueue (clipped into the bounds) when its study is new. `progress`:
    a tqdm bar over the completed trials of all studies (resumed ones count from where they stand).
    """
    runs = []
    for p in problems:
        limits = {**settings.bounds, **p.trust}  # a problem's trust region narrows the configured bounds
        space = space_of(p.searched, limits)
        fixed = {k: v for k, v in p.params.items() if k not in p.searched}
        name = study_name(p.key, tag, space, fixed, settings, twin_key)
        sampler = make_sampler(settings.sampler, settings.seed, settings.n_startup)
        study = open_study(Path(db_path), name, sampler, "minimize")
        if not study.trials:
            for w in (warm or {}).get(p.name, []):
                study.enqueue_trial(clip({k: w[k] for k in p.searched}, limits), skip_if_exists=True)
        runs.append({"p": p, "space": space, "study": study, "seen": {}})
    if settings.ask_workers > 1:  # the proposals come from worker processes (see propose_parallel)
        logging.getLogger("palpation.calibration.search").setLevel(logging.WARNING)  # 'left running' per trial
    done0 = sum(min(completed(r["study"]), settings.n_trials) for r in runs)
    trials = bar(total=settings.n_trials * len(runs), initial=done0, desc=f"recalibrate {tag}", unit="trial",
                 enabled=progress, leave=False)
    while True:
        asks = []
        if settings.ask_workers > 1:
            propose_parallel(db_path, [r["study"].study_name for r in runs], [r["space"] for r in runs], settings)
        for run in runs:
            batch = next_batch(run["study"], run["space"], settings.n_trials, settings.n_startup,
                               settings.batch_size)  # a killed run's last batch comes first
            asks += [(run, trial, props) for trial, props in batch]
        if not asks:
            break
        fresh = [(run, props) for run, _, props in asks if _key(props) not in run["seen"]]
        jobs, spans = [], []
        for run, props in fresh:
            targets = run["p"].fit_targets()
            spans.append((len(jobs), targets))
            jobs += [(t.state, {**run["p"].params, **props}) for t in targets]
        markers, failed = simulate(jobs) if jobs else (np.zeros((0, 127, 2)), np.zeros(0, bool))
        for (run, props), (start, targets) in zip(fresh, spans):
            block, bad = markers[start:start + len(targets)], failed[start:start + len(targets)]
            if bad.any() or not np.all(np.isfinite(block)):
                run["seen"][_key(props)] = (settings.worst_px, {"diverged": 1.0})
                continue
            mae = {t.name: marker_mae_px(m, t.markers) for t, m in zip(targets, block)}
            value = float(np.mean(list(mae.values())))
            run["seen"][_key(props)] = (min(value, settings.worst_px),
                                        {"diverged": 0.0, **{f"mae_px/{k}": v for k, v in mae.items()}})
        for run, trial, props in asks:
            value, attrs = run["seen"][_key(props)]
            for k, v in attrs.items():
                trial.set_user_attr(k, v)
            run["study"].tell(trial, value)
        trials.update(len(asks))
    trials.close()
    out = {}
    for run in runs:
        best = best_trial(run["study"])
        out[run["p"].name] = {"params": dict(best.params), "value": float(best.value), "trial": best.number,
                              "study": run["study"].study_name, "n_trials": completed(run["study"]),
                              "ranked": [dict(t.params) for t in ranked_trials(run["study"])[:RANKED]]}
    return out


_POOL: dict = {}


def _one_thread() -> None:
    import os  # before torch is imported by the GP sampler: one thread per worker, the workers share the cores
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"


def _propose_one(db_path: str, name: str, space: list, s: SearchSettings) -> None:
    study = open_study(Path(db_path), name, make_sampler(s.sampler, s.seed, s.n_startup), "minimize")
    next_batch(study, space, s.n_trials, s.n_startup, s.batch_size)


def propose_parallel(db_path: Path, names: list[str], spaces: list, s: SearchSettings) -> None:
    """Ask every study for its next batch in `s.ask_workers` processes (a GP proposal costs ~0.5 s of CPU
    and 60 self-test problems ask thousands of them per round; the twin batch on a GPU takes seconds).

    Each worker opens the study from the study file with the sampler state the last proposal saved and
    leaves its trials RUNNING with their parameters; the caller's next_batch then picks them up as an
    interrupted batch (calibration.search.interrupted), the same path a resumed search takes. Every study
    is asked by one worker at a time and told between rounds, so the proposals do not depend on the
    scheduling: a fixed seed gives the same search as the serial path (tested)."""
    import atexit
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    key = s.ask_workers
    if key not in _POOL:  # spawn: the parent may hold a CUDA context (the twin), the workers need none
        _POOL[key] = ProcessPoolExecutor(max_workers=key, mp_context=multiprocessing.get_context("spawn"),
                                         initializer=_one_thread)
        atexit.register(_POOL[key].shutdown)
    futures = [_POOL[key].submit(_propose_one, str(db_path), n, sp, s) for n, sp in zip(names, spaces)]
    for f in futures:
        f.result()


RANKED = 10  # best trials returned per study: the local finish (loop.polish) picks distinct starts among them


def ranked_trials(study: optuna.Study) -> list[optuna.trial.FrozenTrial]:
    """Completed trials that did not diverge, best first (ties: the earlier trial)."""
    ok = [t for t in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
          if not t.user_attrs.get("diverged", 0.0)]
    return sorted(ok, key=lambda t: (t.value, t.number))


def best_trial(study: optuna.Study) -> optuna.trial.FrozenTrial:
    ok = ranked_trials(study)
    if not ok:
        raise ValueError(f"loop study '{study.study_name}': every trial diverged; narrow the bounds in "
                         "loop.effects.PARAMS or lower the nominal steps (loop.method.steps)")
    return ok[0]


def _key(params: Mapping[str, float]) -> tuple:
    return tuple(sorted((k, float(v)) for k, v in params.items()))
