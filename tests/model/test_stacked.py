"""Seeds trained together (model.stacked) against the same seeds trained apart (train.fit)."""

import numpy as np
import pytest
import torch

from palpation.model import ModelConfig, TrainConfig
from palpation.model.evaluate import predict
from palpation.model import stacked
from palpation.model.stacked import GivenNoise, fit_seeds, predict_seeds
from palpation.model.train import fit

COMPACT = ModelConfig("compact", 56, 64, 32)
# 3 epochs with patience 1: a seed whose val score does not improve stops early, apart and together
TINY = TrainConfig(batch_size=2, epochs=3, train_batches=1, val_batches=1, patience=1)


def test_given_masks_are_the_masks_f_dropout_draws():
    x, p = torch.randn(40, 9), 0.3
    torch.manual_seed(5)
    drawn = torch.nn.functional.dropout(x, p, training=True)
    torch.manual_seed(5)  # masks drawn apart, on ones, then applied: the same numbers
    feed = {"record": None, "masks": [torch.nn.functional.dropout(torch.ones_like(x), p, training=True)]}
    assert torch.equal(GivenNoise(p, feed)(x), drawn)


def test_seeds_must_be_distinct():
    with pytest.raises(ValueError, match="distinct"):
        fit_seeds(None, None, None, None, None, TINY, [1, 1])


def test_together_equals_apart_up_to_batched_rounding(meat_l2):
    rest, topo, sets = meat_l2
    seeds = [3, 4]
    apart = [fit(sets["train"], sets["val"], rest, topo, COMPACT, TINY, seed=s) for s in seeds]
    together = fit_seeds(sets["train"], sets["val"], rest, topo, COMPACT, TINY, seeds)
    assert min(len(a.history) for a in apart) < TINY.epochs  # early stopping is exercised
    for a, t in zip(apart, together):
        # the same draws: normalisation clips, epochs run, checkpoint chosen, val confusion counts
        assert a.stats == t.stats and a.best_epoch == t.best_epoch and len(a.history) == len(t.history)
        for ha, ht in zip(a.history, t.history):
            assert {k: v for k, v in ha.items() if k != "train/loss"} == \
                   {k: v for k, v in ht.items() if k != "train/loss"}
            assert ht["train/loss"] == pytest.approx(ha["train/loss"], rel=1e-5)
        # batched matmuls round differently (~1e-7 per forward); a few Adam steps keep it far below 1e-4
        for (name, wa), wt in zip(a.model.state_dict().items(), t.model.state_dict().values()):
            assert torch.allclose(wa.float(), wt.float(), rtol=1e-4, atol=1e-5), name
        pa = predict(a.model, sets["val"], a.stats, rest, topo, 2)[0]
        pt = predict(t.model, sets["val"], t.stats, rest, topo, 2)[0]
        assert np.abs(pa - pt).max() < 1e-5
        assert len(t.steps) == 2 * len(t.history)  # per-batch losses + one row per epoch
    alone = [predict(t.model, sets["val"], t.stats, rest, topo, 3) for t in together]
    assert not np.allclose(alone[0][0], alone[1][0])
    # scoring all seeds in one vmapped forward per batch: each seed's own scores, labels in clip order
    at_once = predict_seeds([t.model for t in together], [t.stats for t in together], sets["val"], rest, topo, 3)
    for (pa, la), (pt, lt) in zip(alone, at_once):
        assert np.array_equal(la, lt) and np.abs(pa - pt).max() < 1e-6


def test_val_batches_kept_between_epochs_score_the_same(meat_l2, monkeypatch):
    rest, topo, sets = meat_l2
    runs = fit_seeds(sets["train"], sets["val"], rest, topo, COMPACT, TINY, [3, 4])
    stack, stats = stacked.Stack([r.model for r in runs]), [r.stats for r in runs]
    fresh = stacked.score_stack(stack, stats, sets["val"], rest, topo, 3)
    for budget, kept in ((10 ** 12, -(-len(sets["val"]) // 3)), (1, 0)):
        monkeypatch.setattr(stacked, "VAL_CACHE_BYTES", budget)
        cache = {}
        first = stacked.score_stack(stack, stats, sets["val"], rest, topo, 3, cache=cache)
        again = stacked.score_stack(stack, stats, sets["val"], rest, topo, 3, cache=cache)  # from the cache
        assert len(cache) == kept
        for (pf, lf), (p1, l1), (p2, l2) in zip(fresh, first, again):
            assert np.array_equal(pf, p1) and np.array_equal(pf, p2) and np.array_equal(lf, l2)
