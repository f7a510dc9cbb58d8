"""The batched Optuna driver: validation, batching, determinism and resume after a kill."""

import math

import pytest

from palpation.calibration.search import (ParamSpec, TrialResult, completed, make_sampler, open_study,
                                          run_search, validate_space)

SPACE = [ParamSpec("E", 1e5, 1e6), ParamSpec("k_n", 1e4, 1e5)]


def bowl(batch):
    """log-space bowl with its optimum at E = 3e5, k_n = 3e4; values above 9e5 'diverge'."""
    out = []
    for p in batch:
        if p["E"] > 9e5:
            out.append(TrialResult(-1.0, True, {}))
            continue
        d = (math.log10(p["E"] / 3e5)) ** 2 + (math.log10(p["k_n"] / 3e4)) ** 2
        out.append(TrialResult(-d, False, {"d": d}))
    return out


def search(db, n_trials=10, seed=0, batch_sizes=None):
    study = open_study(db, "bowl", make_sampler("gp", seed, 5), "maximize")
    sizes = []

    def evaluate(batch):
        sizes.append(len(batch))
        return bowl(batch)

    run_search(study, SPACE, n_trials, 5, 1, evaluate)
    if batch_sizes is not None:
        batch_sizes.extend(sizes)
    return study


@pytest.mark.parametrize("bad, match", [
    ([ParamSpec("E", 1e6, 1e5)], "low < high"),
    ([ParamSpec("E", 0.0, 1e5)], "must be > 0"),
    ([ParamSpec("youngs", 1.0, 2.0)], "unknown parameter 'youngs'"),
    ([], "empty"),
])
def test_bad_spaces_are_rejected(bad, match):
    with pytest.raises(ValueError, match=match):
        validate_space(bad, known={"E", "k_n"})


def test_startup_batch_then_sequential_and_improves(tmp_path):
    sizes = []
    study = search(tmp_path / "s.db", batch_sizes=sizes)
    assert sizes[0] == 5 and all(s == 1 for s in sizes[1:]) and sum(sizes) == 10
    startup_best = max(t.value for t in study.trials[:5])
    assert study.best_value >= startup_best
    assert study.best_value > -0.1  # the GP finds the bowl's neighbourhood within 10 trials


def test_same_seed_same_trials_in_either_storage(tmp_path):
    a = search(tmp_path / "a.db")
    b = search(tmp_path / "b.db")
    c = search(tmp_path / "c.journal")  # the loop's storage: the same search
    assert [t.params for t in a.trials] == [t.params for t in b.trials] == [t.params for t in c.trials]


def test_unknown_study_file_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"s\.sqlite: a study file must end in \.db"):
        open_study(tmp_path / "s.sqlite", "bowl", make_sampler("gp", 0, 5), "maximize")


@pytest.mark.parametrize("suffix", [".db", ".journal"])
def test_resume_after_kill(tmp_path, suffix):
    """A trial asked by a process that died before proposing it is proposed and finished on resume."""
    db = tmp_path / f"r{suffix}"
    study = open_study(db, "bowl", make_sampler("gp", 0, 5), "maximize")
    run_search(study, SPACE, 3, 5, 1, bowl)
    study.ask()  # left RUNNING without a proposal, as by a killed process
    resumed = search(db, n_trials=6)
    assert completed(resumed) == 6
    assert [t.state.name for t in resumed.trials] == ["COMPLETE"] * 6


KILLED_SEARCH = """
import os, signal, sys
from pathlib import Path
import optuna
sys.path.insert(0, {tests!r})
from test_search import SPACE, bowl
from palpation.calibration.search import make_sampler, open_study, run_search
calls = []
def die_on(n):
    calls.append(1)
    if len(calls) == n:
        os.kill(os.getpid(), signal.SIGKILL)
def evaluate(batch):
    if {where!r} == "evaluate":
        die_on(3)  # inside the third batch: its trials asked and proposed, not told
    return bowl(batch)
sample = optuna.samplers.GPSampler.sample_relative
def sample_relative(self, *args):
    die_on(5)  # while proposing trial 4, the second of the GP batch after a startup batch of 3
    return sample(self, *args)
if {where!r} == "propose":
    optuna.samplers.GPSampler.sample_relative = sample_relative
run_search(open_study(Path({db!r}), "bowl", make_sampler("gp", 0, 3), "maximize"), SPACE, 8, 3, 2, evaluate)
"""


@pytest.mark.parametrize("suffix", [".db", ".journal"])
@pytest.mark.parametrize("where", ["evaluate", "propose"])
def test_resume_after_sigkill_is_exact(tmp_path, where, suffix):
    """A search killed inside a batch and resumed makes the same trials as one never interrupted."""
    import subprocess
    import sys
    from pathlib import Path

    whole = open_study(tmp_path / f"whole{suffix}", "bowl", make_sampler("gp", 0, 3), "maximize")
    run_search(whole, SPACE, 8, 3, 2, bowl)
    db = tmp_path / f"killed{suffix}"
    code = KILLED_SEARCH.format(tests=str(Path(__file__).parent), db=str(db), where=where)
    assert subprocess.run([sys.executable, "-c", code], timeout=300).returncode == -9
    killed = open_study(db, "bowl", make_sampler("gp", 0, 3), "maximize")
    left = [(t.state.name, sorted(t.params)) for t in killed.trials[3:]]
    assert left == {"evaluate": [("COMPLETE", ["E", "k_n"])] * 2 + [("RUNNING", ["E", "k_n"])] * 2,
                    "propose": [("RUNNING", ["E", "k_n"]), ("RUNNING", [])]}[where]
    run_search(killed, SPACE, 8, 3, 2, bowl)
    assert [(t.number, t.state.name, t.params, t.value) for t in killed.trials] == \
        [(t.number, t.state.name, t.params, t.value) for t in whole.trials]


def test_journal_storage_is_reused_and_sees_other_writers(tmp_path):
    """A journal is replayed once per process: a second open reuses the storage, which still sees trials written
    through another storage (as by a proposer process); a replaced file is read afresh."""
    import optuna

    from palpation.calibration import search as s

    db = tmp_path / "loop.journal"
    first = s.study_storage(db)
    assert s.study_storage(db) is first
    other = optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(str(db)))
    run_search(optuna.create_study(storage=other, study_name="bowl", sampler=make_sampler("gp", 0, 3),
                                   direction="maximize"), SPACE, 4, 3, 1, bowl)
    seen = open_study(db, "bowl", make_sampler("gp", 0, 3), "maximize")
    assert seen._storage is first and completed(seen) == 4
    db.unlink()
    run_search(open_study(db, "cone", make_sampler("gp", 0, 3), "maximize"), SPACE, 2, 3, 1, bowl)
    fresh = s.study_storage(db)
    assert fresh is not first and [x.study_name for x in fresh.get_all_studies()] == ["cone"]
