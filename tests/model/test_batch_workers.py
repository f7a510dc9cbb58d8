"""Batches built in worker processes (model.batch_workers) against batches built in the training process."""

import os
import queue

import numpy as np
import pytest
import torch

from palpation.graph.batch import STEP_FIELDS, make_batch, step_arrays
from palpation.model import ModelConfig, TrainConfig
from palpation.model import batch_workers
from palpation.model.stacked import fit_seeds
from palpation.model.train import norm_stats

COMPACT = ModelConfig("compact", 56, 64, 32)
# every draw of the robust recipe, a last batch shorter than the others (24 clips in 5s), an early stop
AUGMENTED = TrainConfig(batch_size=5, epochs=3, train_batches=None, val_batches=1, patience=1, rotation="consistent",
                        jitter_px=0.2, marker_dropout=0.05, displacement_scale=0.2, norm_stats="full")


def test_step_arrays_are_make_batch_fields(meat_l2):
    rest, topo, sets = meat_l2
    stats = norm_stats(sets["train"], rest, topo, AUGMENTED, np.random.default_rng(0))
    m, lab = sets["train"].gather(np.arange(3))
    data, arrays = make_batch(m, lab, rest, topo, stats), step_arrays(m, lab, rest, topo, stats)
    for name in STEP_FIELDS:
        assert arrays[name].dtype == np.float32 and torch.equal(torch.from_numpy(arrays[name]), getattr(data, name))


def test_workers_train_exactly_as_the_training_process(meat_l2):
    rest, topo, sets = meat_l2
    assert len(sets["train"]) % AUGMENTED.batch_size  # the short last batch is exercised
    runs = [fit_seeds(sets["train"], sets["val"], rest, topo, COMPACT, AUGMENTED, [3, 4, 5], batch_workers=w)
            for w in (False, True)]
    assert min(len(r.history) for r in runs[0]) < AUGMENTED.epochs  # early stopping is exercised
    for inproc, worker in zip(*runs):  # the same draws in the same order: bit for bit on the CPU
        assert inproc.history == worker.history and inproc.steps == worker.steps
        assert inproc.stats == worker.stats and inproc.best_epoch == worker.best_epoch  # the worker drew the stats
        for (name, a), b in zip(inproc.model.state_dict().items(), worker.model.state_dict().values()):
            assert torch.equal(a, b), name


def test_a_failing_worker_is_reported_with_its_traceback(meat_l2, monkeypatch):
    rest, topo, sets = meat_l2

    def broken(*args):
        raise ValueError("no clips here")

    monkeypatch.setattr(batch_workers, "training_batch", broken)  # the forked worker inherits it
    with pytest.raises(RuntimeError, match=r"batch worker of seed 3 failed:(.|\n)*no clips here"):
        fit_seeds(sets["train"], sets["val"], rest, topo, COMPACT, AUGMENTED, [3], batch_workers=True)


def test_a_worker_stops_when_its_training_process_is_gone(monkeypatch):
    parent = os.getpid()
    empty = queue.Queue()
    monkeypatch.setattr(batch_workers, "POLL_S", 0.01)
    monkeypatch.setattr(batch_workers.os, "getppid", lambda: parent)
    empty.put(2)
    assert batch_workers._free_slot(empty, parent) == 2
    monkeypatch.setattr(batch_workers.os, "getppid", lambda: 1)  # re-parented: the training process died
    assert batch_workers._free_slot(empty, parent) is None
