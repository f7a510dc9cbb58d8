import math

import numpy as np
import pytest
import torch

from palpation.graph.clips import ClipSet
from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.layout import rest_layout
from palpation.graph.sources import load_dataset
from palpation.graph.synthetic import write_meat
from palpation.model import STGNN, ModelConfig, TrainConfig
from palpation.model.checkpoint import load_checkpoint, save_checkpoint
from palpation.model.evaluate import predict
from palpation.model.train import fit, focal_loss, param_groups

COMPACT = ModelConfig("compact", 56, 64, 32)
TINY = TrainConfig(batch_size=2, epochs=2, train_batches=2, val_batches=1)


def test_focal_loss_matches_formula():
    logits, y, alpha, gamma = torch.tensor([2.0, -1.0, 0.5]), torch.tensor([1.0, 0.0, 0.0]), 0.9, 3.0
    p = 1 / (1 + np.exp(-logits.numpy()))
    expected = np.mean([alpha * (1 - p[0]) ** 3 * -math.log(p[0]),
                        (1 - alpha) * p[1] ** 3 * -math.log(1 - p[1]),
                        (1 - alpha) * p[2] ** 3 * -math.log(1 - p[2])])
    assert focal_loss(logits, y, alpha, gamma).item() == pytest.approx(expected, rel=1e-5)


def test_no_weight_decay_on_bias_and_bn():
    decay, no_decay = param_groups(STGNN(1, COMPACT), 1e-4)
    model = STGNN(1, COMPACT)
    names = {n for n, _ in model.named_parameters() if "bias" in n or "bn" in n}
    assert len(no_decay["params"]) == len(names) and no_decay["weight_decay"] == 0
    assert decay["weight_decay"] == 1e-4


@pytest.fixture(scope="module")
def meat(tmp_path_factory):
    rest = rest_layout("ideal")
    path = write_meat(tmp_path_factory.mktemp("meat") / "meat.npz", rest, n_frames=(8,) * 5, n_val=2)
    topo = clip_topology(spatial_edges(rest), 3)
    sets = {s: ClipSet(load_dataset("meat", path, s), 3, rest) for s in ("train", "val")}
    return rest, topo, sets


def test_same_seed_bit_identical_and_checkpoint_round_trip(meat, tmp_path):
    rest, topo, sets = meat
    runs = [fit(sets["train"], sets["val"], rest, topo, COMPACT, TINY, seed=3) for _ in range(2)]
    scores = [predict(r.model, sets["val"], r.stats, rest, topo, 2) for r in runs]
    assert np.array_equal(scores[0][0], scores[1][0]) and runs[0].history == runs[1].history
    assert runs[0].stats == runs[1].stats
    other = fit(sets["train"], sets["val"], rest, topo, COMPACT, TINY, seed=4)
    assert not np.array_equal(predict(other.model, sets["val"], other.stats, rest, topo, 2)[0], scores[0][0])

    save_checkpoint(tmp_path / "c.pt", runs[0].model, COMPACT, runs[0].stats, rest)
    model, stats, rest_loaded, _ = load_checkpoint(tmp_path / "c.pt")
    assert stats == runs[0].stats and np.allclose(rest_loaded, rest)
    assert np.array_equal(predict(model, sets["val"], stats, rest, topo, 2)[0], scores[0][0])


def test_val_scores_are_the_returned_models(meat):
    """fit keeps the best epoch's val scores (the post-hoc calibration's input): the bits predict gives with the
    returned model, also when an earlier epoch wins."""
    rest, topo, sets = meat
    cfg = TrainConfig(batch_size=2, epochs=3, train_batches=2, val_batches=2, select_metric="ap")
    run = fit(sets["train"], sets["val"], rest, topo, COMPACT, cfg, seed=5)
    again = predict(run.model, sets["val"], run.stats, rest, topo, 2, 2)
    assert np.array_equal(run.val_scores[0], again[0]) and np.array_equal(run.val_scores[1], again[1])
    scores = [row["val/ap"] for row in run.history]
    assert run.best_epoch == int(np.argmax(scores)) == 0 and run.best_val_score == max(scores)  # seed 5: epoch 0


def test_progress_bar_on_stderr_only_when_asked_and_results_unchanged(meat, capsys):
    rest, topo, sets = meat
    quiet = fit(sets["train"], sets["val"], rest, topo, COMPACT, TINY, seed=3, progress=False)
    assert "train" not in capsys.readouterr().err
    shown = fit(sets["train"], sets["val"], rest, topo, COMPACT, TINY, seed=3, progress=True)
    err = capsys.readouterr().err
    # 2 epochs x 2 batches; captured stderr is no terminal, so the bar redraws sparsely (log mode)
    assert "train" in err and "4/4" in err and "epoch 2/2 loss" in err
    assert shown.history == quiet.history  # the bar draws no random numbers
    assert all(torch.equal(a, b) for a, b in zip(shown.model.state_dict().values(),
                                                 quiet.model.state_dict().values()))


def test_remove_common_motion_travels_with_the_statistics(meat, tmp_path):
    """The opt-in input transform: fitted with it, the statistics carry it through the checkpoint, so scoring the
    same clips with a whole-field drift added per frame gives the same scores; without it the scores move."""
    from dataclasses import replace

    rest, topo, sets = meat
    on = fit(sets["train"], sets["val"], rest, topo, COMPACT, replace(TINY, remove_common_motion=True), seed=3)
    assert on.stats.remove_common_motion
    save_checkpoint(tmp_path / "c.pt", on.model, COMPACT, on.stats, rest)
    model, stats, _, _ = load_checkpoint(tmp_path / "c.pt")
    assert stats.remove_common_motion

    class Drifted:  # the val clips with a per-frame translation of every marker (a trial-specific drift)
        def __init__(self, clips, px):
            self.clips, self.px = clips, px

        def __len__(self):
            return len(self.clips)

        def gather(self, idx, *args, **kwargs):
            m, lab = self.clips.gather(idx, *args, **kwargs)
            return m + np.random.default_rng(len(idx)).normal(0, self.px, (*m.shape[:2], 1, 2)).astype(m.dtype), lab

    clean = predict(model, sets["val"], stats, rest, topo, 2)[0]
    drifted = predict(model, Drifted(sets["val"], 10.0), stats, rest, topo, 2)[0]
    assert np.allclose(drifted, clean, atol=1e-3)  # float32 rounding of the features only
    off = fit(sets["train"], sets["val"], rest, topo, COMPACT, TINY, seed=3)
    assert not off.stats.remove_common_motion
    moved = predict(off.model, Drifted(sets["val"], 10.0), off.stats, rest, topo, 2)[0]
    assert not np.allclose(moved, predict(off.model, sets["val"], off.stats, rest, topo, 2)[0], atol=1e-3)
