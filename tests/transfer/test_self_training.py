"""Self-training on agreed pseudo-labels (recipe.pseudo, model.self_training): the masked loss, the
pseudo-labelled clips, the scored set's labels never read, and the option off by default."""

import json

import numpy as np
import pytest
import torch

from palpation.graph.layout import rest_layout
from palpation.graph.pseudo import NO_LABEL, PSEUDO, ClipSets, label_counts
from palpation.io import save_json, save_npz
from palpation.metrics.scores import Scores, save_scores
from palpation.model.train import coded_targets, focal_loss, masked_focal_loss, pseudo_focal_loss
from palpation.readers import read_npz
from palpation.model.pseudo_labels import agreed_labels
from palpation.model.self_training import pseudo_clips

from tests.apps.test_train_app import TINY, compose_train

SEEDS = (0, 1, 2)


def test_masked_loss_ignores_unlabelled_markers():
    g = torch.Generator().manual_seed(0)
    logits = torch.randn(200, generator=g, requires_grad=True)
    targets = (torch.rand(200, generator=g) < 0.2).float()
    weight = torch.where(torch.rand(200, generator=g) < 0.3, 0.0, 1.0)
    weight[:20] = torch.where(weight[:20] > 0, 0.5, 0.0)  # some pseudo-labels of weight 0.5

    def loss_and_grad(t):
        logits.grad = None
        loss = masked_focal_loss(logits, t, weight, 0.8, 3.0)
        loss.backward()
        return loss.item(), logits.grad.clone()

    loss, grad = loss_and_grad(targets)
    flipped = torch.where(weight == 0, 1 - targets, targets)  # every unlabelled marker's target changed
    loss2, grad2 = loss_and_grad(flipped)
    assert loss == loss2 and torch.equal(grad, grad2) and grad[weight == 0].abs().max() == 0
    assert loss_and_grad(torch.where(weight > 0, 1 - targets, targets))[0] != loss  # a labelled one counts
    # all labelled at weight 1: the plain focal loss
    ones = torch.ones(200)
    assert masked_focal_loss(logits, targets, ones, 0.8, 3.0).item() == pytest.approx(
        focal_loss(logits, targets, 0.8, 3.0).item(), rel=1e-6)


def test_label_codes_read_back_as_targets_and_weights():
    codes = torch.tensor([0.0, 1.0, PSEUDO + 0.0, PSEUDO + 1.0, NO_LABEL])
    targets, weight = coded_targets(codes, 0.25)
    assert targets.tolist() == [0, 1, 0, 1, 0] and weight.tolist() == [1, 1, 0.25, 0.25, 0]
    assert label_counts(np.array([0, 1, 1, PSEUDO, PSEUDO + 1, NO_LABEL])) == (3, 5)
    logits = torch.randn(5)
    assert pseudo_focal_loss(logits[:2], codes[:2], 0.7, 2.0, 0.25).item() == pytest.approx(
        focal_loss(logits[:2], codes[:2], 0.7, 2.0).item(), rel=1e-6)  # plain labels: the plain loss


def write_teachers(root, sets, config, test_on, train_on, clip_len=3, agree=0.6, labels_from=None):
    """Teacher runs of `config` whose seeds' scores of `test_on` agree on a known share of the markers: where
    `agree` (a fixed random mask) all seeds call the same side, elsewhere they split. Their stored labels are
    random (a reader of them would see garbage)."""
    from palpation.graph.clips import ClipSet
    from palpation.graph.sources import load_dataset

    clips = ClipSet(load_dataset(test_on, sets[test_on], "test"), clip_len, rest_layout("ideal"))
    seq, frame = clips.central_frames()
    rng = np.random.default_rng(7)
    n = len(seq) * 127
    side, sure = rng.random(n) < 0.3, rng.random(n) < agree
    probs = []
    for s in SEEDS:
        p = np.where(side, 0.8, 0.2) + rng.uniform(-0.05, 0.05, n)
        if s == 1:
            p = np.where(sure, p, 1 - p)  # one seed dissents where the seeds are not sure
        probs.append(p.astype(np.float32))
    folder = root / config / f"L{clip_len}"
    for s, p in zip(SEEDS, probs):
        out = folder / f"seed{s}"
        save_scores(out / "scores.npz", Scores(p, rng.integers(0, 2, n).astype(np.int8), seq, frame))
        save_json(out / "metrics.json", {"config": config, "train_on": train_on, "test_on": test_on,
                                         "clip_len": clip_len, "seed": s})
    return np.stack(probs), seq, frame


def _base(sets):
    return ["model=compact", "clip_len=3", "track=false", "progress=false", *TINY,
            *(f"data.{k}={v}" for k, v in sets.items())]


def test_pseudo_clips_hold_only_the_agreed_markers(train_sets, tmp_path):
    from palpation.apps.train import job_from_config

    teach = tmp_path / "teach"
    probs, seq, frame = write_teachers(teach, train_sets, "A-to-C", "meat", "sim")
    write_teachers(teach, train_sets, "A-to-B", "silicone", "sim")
    job = job_from_config(compose_train(["experiment=A-to-B", *_base(train_sets), "recipe.pseudo=other_real",
                                         "recipe.pseudo_min_agree=1", f"recipe.pseudo_from={teach}"]))
    clips, record = pseudo_clips(job, rest_layout("ideal"))
    labels, keep = agreed_labels(probs)
    assert 0 < keep.sum() < keep.size and record["set"] == "meat" and not record["transductive"]
    assert record["markers_kept"] == keep.sum() and record["teacher_seeds"] == list(SEEDS)
    got = np.stack([clips.seqs.labels[s][f] for s, f in zip(seq, frame)]).ravel()
    assert np.array_equal(got, np.where(keep, PSEUDO + labels, NO_LABEL))  # Meat: every frame scored once
    # the transductive choice reads the scored set (Silicone), whose edge frames no clip is centred on: no label
    job = job_from_config(compose_train(["experiment=A-to-B", *_base(train_sets), "recipe.pseudo=test_set",
                                         f"recipe.pseudo_from={teach}"]))
    clips, record = pseudo_clips(job, rest_layout("ideal"))
    assert record["set"] == "silicone" and record["transductive"] and record["from"].endswith("A-to-B/L3")
    assert (clips.seqs.labels[0][0] == NO_LABEL).all() and (clips.seqs.labels[0][-1] == NO_LABEL).all()
    both = ClipSets([clips, clips])
    m, lab = both.gather(np.array([len(clips) + 1, 0, 1]), np.array([2, 0, 0]), consistent=True)
    m1, lab1 = clips.gather(np.array([1]), np.array([2]), consistent=True)
    assert np.array_equal(m[0], m1[0]) and np.array_equal(lab[0], lab1[0]) and len(both) == 2 * len(clips)


def _garbage(path, out):
    """A copy of a real set with random labels (same markers, same layout file)."""
    z = dict(np.load(path))
    z["labels"] = np.random.default_rng(3).integers(0, 2, z["labels"].shape).astype(z["labels"].dtype)
    save_npz(out, **z)
    if path.endswith("meat.npz"):
        out.with_suffix(".json").write_text(open(path[:-4] + ".json").read())
    return str(out)


@pytest.mark.parametrize("pseudo, seeds", [("test_set", "seed=0"), ("other_real", "seeds=[0,1]")])
def test_the_scored_sets_labels_are_never_read(train_sets, tmp_path, pseudo, seeds):
    """Garbage labels in the scored set (Silicone) and in the pseudo-labelled set change nothing in training: the
    same checkpoint bytes and history; only the test metrics move."""
    from palpation.apps.train import run

    teach = tmp_path / "teach"
    write_teachers(teach, train_sets, "A-to-C", "meat", "sim")
    write_teachers(teach, train_sets, "A-to-B", "silicone", "sim")
    bad = {**train_sets, "silicone": _garbage(train_sets["silicone"], tmp_path / "silicone.npz")}
    if pseudo == "other_real":
        bad["meat"] = _garbage(train_sets["meat"], tmp_path / "meat.npz")
    opts = ["experiment=A-to-B", seeds, "recipe=robust", "recipe.calibration=none", f"recipe.pseudo={pseudo}",
            f"recipe.pseudo_from={teach}", "recipe.pseudo_weight=0.5"]
    out = {}
    for name, sets in (("good", train_sets), ("bad", bad)):
        m = run(compose_train([*opts, *_base(sets)]), tmp_path / name)
        out[name] = m if isinstance(m, list) else [m]
    sub = "seed0" if seeds.startswith("seeds") else ""
    good, bad_run = (tmp_path / n / sub for n in ("good", "bad"))
    assert (good / "checkpoint.pt").read_bytes() == (bad_run / "checkpoint.pt").read_bytes()
    assert out["good"][0]["history"] == out["bad"][0]["history"]
    assert out["good"][0]["test"] != out["bad"][0]["test"]  # the garbage labels are there, and only scored
    rec = out["good"][0]["pseudo_labels"]
    assert rec["transductive"] == (pseudo == "test_set") and rec["weight"] == 0.5
    assert np.array_equal(read_npz(good / "scores.npz", ("probs",))["probs"],
                          read_npz(bad_run / "scores.npz", ("probs",))["probs"])


def test_off_by_default_and_bad_settings_refused(train_sets, tmp_path):
    from palpation.apps.train import job_from_config, run

    for recipe in ("reference", "robust", "better", "calibrated", "quick"):
        t = job_from_config(compose_train([f"recipe={recipe}"])).train
        assert (t.pseudo, t.pseudo_from, t.pseudo_weight) == ("none", None, 1.0)
    m = run(compose_train(["experiment=A-to-B", "seed=0", *_base(train_sets)]), tmp_path / "ref")
    saved = json.loads((tmp_path / "ref" / "metrics.json").read_text())
    assert "pseudo_labels" not in m and "pseudo_labels" not in saved
    with pytest.raises(ValueError, match="give both"):
        job_from_config(compose_train(["recipe.pseudo=other_real"]))
    with pytest.raises(Exception, match="pseudo_margin"):
        job_from_config(compose_train(["recipe.pseudo_margin=0.6"]))
    teach = tmp_path / "teach"
    write_teachers(teach, train_sets, "A-to-B", "silicone", "sim")
    on = [f"recipe.pseudo_from={teach}", *_base(train_sets)]
    with pytest.raises(ValueError, match="pseudo=other_real has no unlabelled set"):
        run(compose_train(["experiment=C-to-B", "seed=0", "recipe.pseudo=other_real", *on]), tmp_path / "cb")
    with pytest.raises(ValueError, match="train each configuration apart"):
        run(compose_train(["experiment=A-to-B", "seeds=[0]", "also_test=[A-to-C:meat]", "recipe.pseudo=test_set",
                           *on]), tmp_path / "x" / "A-to-B" / "L3")
    with pytest.raises(ValueError, match="one teacher folder of runs scored on meat"):
        run(compose_train(["experiment=A-to-B", "seed=0", "recipe.pseudo=other_real", *on]), tmp_path / "ab")
    for s in SEEDS:  # teachers that scored other clips (another window rule): refused
        path = teach / "A-to-B" / "L3" / f"seed{s}" / "scores.npz"
        z = dict(np.load(path))
        save_npz(path, **{**z, "frame": z["frame"] + 1})
    with pytest.raises(ValueError, match="sequence, frame ids differ"):
        run(compose_train(["experiment=A-to-B", "seed=0", "recipe.pseudo=test_set", *on]), tmp_path / "moved")
