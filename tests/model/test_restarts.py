"""Restarts (model.restarts): several starts per seed, the best on val kept; apart and stacked alike."""

import math
from dataclasses import replace

import pytest
import torch

from palpation.model import ModelConfig, TrainConfig
from palpation.model.restarts import STRIDE, best_start, fit_restarts, fit_seeds_restarts, start_seeds
from palpation.model.train import FitResult, fit

COMPACT = ModelConfig("compact", 56, 64, 32)
TINY = TrainConfig(batch_size=2, epochs=2, train_batches=2, val_batches=2, select_metric="ap")


def _result(score):
    return FitResult(model=None, stats=None, best_epoch=0, best_val_score=score)


def test_start_seeds_and_the_choice_rule():
    assert start_seeds(4, 1) == [4] and start_seeds(4, 3) == [4, 4 + STRIDE, 4 + 2 * STRIDE]
    assert best_start([_result(s) for s in (0.2, 0.5, 0.5)]) == 1  # the first of equals
    assert best_start([_result(math.nan), _result(0.1)]) == 1  # a NaN val score never wins
    with pytest.raises(ValueError, match="train.restarts=0"):
        start_seeds(0, 0)
    with pytest.raises(ValueError, match="restarts must be >= 1"):
        TrainConfig(restarts=0)


def test_the_kept_start_is_the_best_on_val_and_is_that_seeds_own_model(meat_l2):
    rest, topo, sets = meat_l2
    seed, cfg = 2, replace(TINY, restarts=3)
    alone = [fit(sets["train"], sets["val"], rest, topo, COMPACT, TINY, s) for s in start_seeds(seed, 3)]
    logged = []
    kept, extra = fit_restarts(sets["train"], sets["val"], rest, topo, COMPACT, cfg, seed,
                               lambda m, step: logged.append(step))
    k = extra["restarts"]["chosen"]
    assert extra["restarts"]["val_scores"] == [a.best_val_score for a in alone]
    assert k == best_start(alone) and len({a.best_val_score for a in alone}) > 1  # the starts differ on val
    for wa, wk in zip(alone[k].model.state_dict().values(), kept.model.state_dict().values()):
        assert torch.equal(wa, wk)  # the kept model is that start's, bit for bit (CPU)
    assert logged == [step for _, step in kept.steps] and logged  # only the kept start's history
    one, none = fit_restarts(sets["train"], sets["val"], rest, topo, COMPACT, TINY, seed)
    assert none == {} and one.best_val_score == alone[0].best_val_score


def test_stacked_restarts_keep_the_same_starts(meat_l2):
    rest, topo, sets = meat_l2
    cfg = replace(TINY, restarts=2)
    apart = [fit_restarts(sets["train"], sets["val"], rest, topo, COMPACT, cfg, s) for s in (0, 1)]
    together, extras = fit_seeds_restarts(sets["train"], sets["val"], rest, topo, COMPACT, cfg, [0, 1])
    for (a, ea), t, s in zip(apart, together, (0, 1)):
        assert extras[s]["restarts"]["chosen"] == ea["restarts"]["chosen"]
        assert extras[s]["restarts"]["val_scores"] == pytest.approx(ea["restarts"]["val_scores"], abs=1e-6)
        assert t.best_epoch == a.best_epoch and t.stats == a.stats
