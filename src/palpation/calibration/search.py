"""A persistent, seeded Optuna search whose trials are evaluated in batches.

The twin simulates many parameter sets as independent environments of one run, so the search asks
the sampler for a batch of proposals, simulates them together, and tells the results back. The study
lives in a file (SQLite or an Optuna journal, `study_storage`): a killed search resumes where it stopped,
and exactly as if it had never stopped. After each proposal the sampler (its random state and caches) is
pickled into the study, so the trials of a killed batch, left RUNNING, are finished first (simulated again
with their recorded proposals, or proposed now if the kill came while proposing) and every later proposal
is the one an uninterrupted search would have made.
"""

from __future__ import annotations

import base64
import json
import logging
import math
import pickle
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import optuna
from optuna.trial import TrialState

from palpation.readers import one_line

log = logging.getLogger(__name__)
SAMPLER_ATTR = "sampler_state"  # study user attrs: the pickled sampler after the last batch's asks
ASKED_ATTR = "sampler_asked"  # and the number of trials the study held then


@dataclass(frozen=True)
class ParamSpec:
    """One searched twin parameter: its name in the twin's parameter registry and its bounds."""

    name: str
    low: float
    high: float
    log: bool = True


@dataclass(frozen=True)
class TrialResult:
    value: float  # objective value; a diverged simulation gets the configured worst value
    diverged: bool
    metrics: dict[str, float]


def validate_space(space: Sequence[ParamSpec], known: set[str]) -> None:
    """Reject unknown names and impossible bounds before any simulation starts."""
    if not space:
        raise ValueError("calibration.params is empty: name at least one twin parameter to search")
    seen = set()
    for p in space:
        if p.name not in known:
            raise ValueError(f"calibration.params: unknown parameter '{p.name}'; known: {sorted(known)}")
        if p.name in seen:
            raise ValueError(f"calibration.params: '{p.name}' is listed twice")
        seen.add(p.name)
        if not (math.isfinite(p.low) and math.isfinite(p.high)) or p.low >= p.high:
            raise ValueError(f"calibration.params.{p.name}: need low < high, got [{p.low}, {p.high}]")
        if p.log and p.low <= 0:
            raise ValueError(f"calibration.params.{p.name}: log-scaled bounds must be > 0, got low={p.low}")


def make_sampler(kind: str, seed: int, n_startup: int) -> optuna.samplers.BaseSampler:
    # GP + expected improvement mirrors the reference's bayes_opt search and is the most sample-efficient
    # choice for a handful of smooth parameters; TPE (constant liar) is for wider spaces and big batches.
    if kind == "gp":
        return optuna.samplers.GPSampler(seed=seed, n_startup_trials=n_startup)
    if kind == "tpe":
        return optuna.samplers.TPESampler(seed=seed, n_startup_trials=n_startup, constant_liar=True)
    if kind == "random":
        return optuna.samplers.RandomSampler(seed=seed)
    raise ValueError(f"calibration.sampler must be gp, tpe or random, got '{kind}'")


def study_storage(path: Path) -> optuna.storages.BaseStorage:
    """The persistent storage of a study file: `*.db` an SQLite database (the calibration: a few trials, and
    `optuna-dashboard sqlite:///...` reads it), `*.journal` an append-only Optuna journal (the loop: hundreds of
    trials a run, where SQLAlchemy's per-call overhead was 18 s of the paper loop's 144 s on an H100; the journal
    does the same calls ~6x faster). Both are safe for several processes (the loop's parallel proposers)."""
    if path.suffix == ".db":  # a generous lock timeout: parallel proposers write to one file at once
        return optuna.storages.RDBStorage(f"sqlite:///{path}", engine_kwargs={"connect_args": {"timeout": 300}})
    if path.suffix == ".journal":
        return _journal(path)
    raise ValueError(f"{path}: a study file must end in .db (SQLite) or .journal (Optuna journal)")


_JOURNALS: dict[str, tuple[tuple[int, int], bytes, int, optuna.storages.JournalStorage]] = {}
_HEAD = 4096  # bytes of a journal that identify it (its first studies' names and start times)


def _journal(path: Path) -> optuna.storages.JournalStorage:
    """One journal storage per file and process, reused: a new storage replays the whole file on its first read
    (the loop's file reaches ~100 MB over a self-test and is opened by every problem and proposer), a reused one
    reads only the lines appended since. A file that was replaced (another inode, another head, or shorter than
    when last seen) gets a fresh storage."""
    key = str(path.resolve())
    if path.exists() and key in _JOURNALS:
        inode, head, size, storage = _JOURNALS[key]
        st = path.stat()
        with open(path, "rb") as f:
            now = f.read(_HEAD)
        if inode == (st.st_dev, st.st_ino) and st.st_size >= size and now.startswith(head):
            _JOURNALS[key] = (inode, now, st.st_size, storage)
            return storage
    storage = optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(str(path)))
    st = path.stat()
    with open(path, "rb") as f:
        _JOURNALS[key] = ((st.st_dev, st.st_ino), f.read(_HEAD), st.st_size, storage)
    return storage


def open_study(db_path: Path, name: str, sampler: optuna.samplers.BaseSampler,
               direction: str) -> optuna.Study:
    db_path.parent.mkdir(parents=True, exist_ok=True)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        study = optuna.create_study(storage=study_storage(db_path), study_name=name, sampler=sampler,
                                    direction=direction, load_if_exists=True)
    except Exception as exc:
        # a journal line that is not JSON, or a .db that is not SQLite; a locked database is not damage
        orig = getattr(exc, "orig", None)
        not_sqlite = isinstance(orig, sqlite3.DatabaseError) and not isinstance(orig, sqlite3.OperationalError)
        if isinstance(exc, (json.JSONDecodeError, UnicodeDecodeError)) or not_sqlite:
            raise ValueError(f"study file {db_path} is damaged ({one_line(orig or exc)}); delete it to start the "
                             "search afresh (its trials are then simulated again)") from None
        raise
    state = study.user_attrs.get(SAMPLER_ATTR)
    if state is not None:
        try:
            study.sampler = pickle.loads(base64.b64decode(state))
        except Exception as exc:  # another Optuna version: resume, but not bit-identically
            log.warning("study '%s': saved sampler state unreadable (%s): a fresh sampler goes on", name, exc)
    return study


def _propose(study: optuna.Study, trial: optuna.Trial, space: Sequence[ParamSpec]) -> dict[str, float]:
    """Suggest every parameter of `trial`, then save the sampler's state in the study (the resume point)."""
    proposal = {p.name: trial.suggest_float(p.name, p.low, p.high, log=p.log) for p in space}
    study.set_user_attr(SAMPLER_ATTR, base64.b64encode(pickle.dumps(study.sampler)).decode())
    study.set_user_attr(ASKED_ATTR, trial.number + 1)
    return proposal


def ask_batch(study: optuna.Study, space: Sequence[ParamSpec], size: int) -> list[tuple[optuna.Trial, dict]]:
    """`size` new trials with their proposals, each made before the next ask (a GP batch sees its earlier
    members)."""
    batch = []
    for _ in range(size):
        trial = study.ask()
        batch.append((trial, _propose(study, trial, space)))
    return batch


def interrupted(study: optuna.Study, space: Sequence[ParamSpec]) -> list[tuple[optuna.Trial, dict]]:
    """The batch a killed search left RUNNING, to finish: trials with a recorded proposal are simulated
    again, the one killed while being proposed gets its proposal now from the saved sampler state.

    The handle comes from Optuna's `Trial(study, trial_id)` constructor, not the public resume (mark the trial
    FAIL and `enqueue_trial` its params, what `RetryFailedTrialCallback` does): measured on toy GP and TPE
    studies (Optuna 5.0, killed at trial 6 of 12), both give 12/12 identical proposals, but the public path
    leaves a FAIL trial and renumbers the resumed one, so a killed+resumed run's trials.csv and loop tables
    would differ from a clean run's (tests/test_workflow_reliability.py requires them equal, without FAIL)."""
    asked = int(study.user_attrs.get(ASKED_ATTR, 0))
    batch = []
    for frozen in sorted(study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)), key=lambda t: t.number):
        trial = optuna.Trial(study, frozen._trial_id)  # the handle study.ask() returned to the dead process
        if all(p.name in frozen.params for p in space):
            if frozen.number >= asked:  # killed between its proposal and the save: later proposals may differ
                log.warning("trial %d: proposed after the saved sampler state; the resume is not exact",
                            frozen.number)
            batch.append((trial, {p.name: frozen.params[p.name] for p in space}))
        else:
            batch.append((trial, _propose(study, trial, space)))
        log.info("trial %d was left running by a killed search: finishing it", frozen.number)
    return batch


def next_batch(study: optuna.Study, space: Sequence[ParamSpec], n_trials: int, n_startup: int,
               batch_size: int) -> list[tuple[optuna.Trial, dict]]:
    """The trials to simulate next: a batch a killed search left unfinished, else the startup (random)
    trials together, then `batch_size` proposals at a time; empty once `n_trials` are complete."""
    batch = interrupted(study, space)
    if batch or (done := completed(study)) >= n_trials:
        return batch
    size = (n_startup - done) if done < n_startup else batch_size
    return ask_batch(study, space, max(1, min(n_trials - done, size)))


def completed(study: optuna.Study) -> int:
    return len(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))


def run_search(study: optuna.Study, space: Sequence[ParamSpec], n_trials: int, n_startup: int,
               batch_size: int, evaluate: Callable[[list[dict[str, float]]], list[TrialResult]],
               on_trial: Callable[[optuna.trial.FrozenTrial, TrialResult], None] | None = None,
               progress: Callable[[int], None] | None = None) -> optuna.Study:
    """Run until the study holds `n_trials` completed trials.

    Startup (random) trials are proposed together; after that each batch holds `batch_size`
    proposals (1 keeps a GP search strictly sequential, as the reference's). A batch a killed search
    left unfinished is simulated first.
    """
    while batch := next_batch(study, space, n_trials, n_startup, batch_size):
        trials, proposals = [t for t, _ in batch], [p for _, p in batch]
        results = evaluate(proposals)
        for trial, result in zip(trials, results, strict=True):
            trial.set_user_attr("diverged", result.diverged)
            for key, value in result.metrics.items():
                trial.set_user_attr(key, value)
            frozen = study.tell(trial, result.value)
            if on_trial is not None:
                on_trial(frozen, result)
        if progress is not None:
            progress(len(batch))
    return study
