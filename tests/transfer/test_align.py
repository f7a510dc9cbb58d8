"""Feature-statistics alignment (graph.align) and the transfer recipe options of the train app (model.domain)."""

import json

import numpy as np
import pytest

from palpation.graph.align import Moments, clip_moments, fit_alignment
from palpation.graph.clips import ClipSet
from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.features import clip_features
from palpation.graph.layout import rest_layout
from palpation.graph.normalise import GROUPS
from palpation.graph.sources import load_dataset

from tests.apps.test_train_app import TINY, compose_train

ARRAYS = {"node": "x", "spatial": "spatial", "temporal": "temporal"}


@pytest.fixture(scope="module")
def toy(train_sets):
    """Sim training clips and Silicone clips made to differ from them: a shifted, sheared and scaled camera."""
    rest = rest_layout("ideal")
    topo = clip_topology(spatial_edges(rest), 3)
    sim = ClipSet(load_dataset("sim", train_sets["sim"], "train"), 3, rest)
    real = load_dataset("silicone", train_sets["silicone"], "test")
    warp = np.array([[1.3, 0.2], [0.0, 0.8]], np.float32)
    real.markers = [(m - rest.mean(0)) @ warp + rest.mean(0) + np.float32([25, -10]) for m in real.markers]
    return rest, topo, sim, ClipSet(real, 3, rest)


def _features(clips, rest, topo, align=None):
    idx = np.arange(len(clips))
    feats = clip_features(clips.gather(idx)[0], rest, topo)
    return feats if align is None else align.apply(feats, clips.windows[idx, 0])


@pytest.mark.parametrize("method", ["meanstd", "coral"])
def test_aligned_features_take_the_training_moments(toy, method):
    rest, topo, sim, real = toy
    source = clip_moments(sim, rest, topo, False)
    before = Moments.of([_features(real, rest, topo)])
    align = fit_alignment(source, real, rest, topo, method, "test_set")
    after = Moments.of([_features(real, rest, topo, align)])
    assert np.abs(before.mean["node"] - source.mean["node"]).max() > 10.0  # the toy shift is there to remove
    assert np.abs(np.diag(before.cov["spatial"]) / np.diag(source.cov["spatial"]) - 1).max() > 0.1  # and the scale
    for g in GROUPS:
        scale = np.sqrt(np.diag(source.cov[g]))
        np.testing.assert_allclose(after.mean[g], source.mean[g], atol=1e-3 * scale.max() + 1e-4)
        np.testing.assert_allclose(np.sqrt(np.diag(after.cov[g])), scale, rtol=2e-3, atol=1e-4)
    # CORAL matches the cross-covariances too (the shear correlates x and y); mean-std matching leaves them
    corr = lambda c: c[0, 1] / np.sqrt(c[0, 0] * c[1, 1])  # noqa: E731
    gap = abs(corr(after.cov["node"]) - corr(source.cov["node"]))
    assert (gap < 1e-3) if method == "coral" else (gap > 1e-2)
    assert not align.transductive or align.stats_from == "test_set"


def test_per_sequence_normalisation_standardises_each_sequence_on_its_own(toy):
    """test_sequence: every scored sequence gets the training moments from its own clips alone (test-time
    normalisation per sequence); a map fitted on the whole set leaves the sequences' own offsets in."""
    rest, topo, sim, real = toy
    real.seqs.markers[1] = real.seqs.markers[1] + np.float32([40, 15])  # a second trial, offset on its own
    source = clip_moments(sim, rest, topo, False)
    per_seq = fit_alignment(source, real, rest, topo, "meanstd", "test_sequence")
    whole = fit_alignment(source, real, rest, topo, "meanstd", "test_set")
    assert per_seq.transductive and sorted(per_seq.maps) == [0, 1]
    seq = real.windows[:, 0]
    for align, exact in ((per_seq, True), (whole, False)):
        feats = _features(real, rest, topo, align)
        for k in (0, 1):
            x = feats.x[seq == k][..., :2].reshape(-1, 2).astype(np.float64)
            err = np.abs(x.mean(0) - source.mean["node"][:2]).max()
            assert (err < 1e-2) if exact else (err > 5.0)
    with pytest.raises(ValueError, match="no statistics for sequence 7"):
        per_seq.apply(clip_features(real.gather(np.arange(2))[0], rest, topo), np.array([7, 7]))


def test_alignment_option_changes_the_test_scores_only_and_is_recorded(train_sets, tmp_path):
    from palpation.apps.train import run

    paths = [f"data.{k}={v}" for k, v in train_sets.items()]
    base = ["experiment=A-to-B", "model=compact", "seed=0", "clip_len=3", "track=false", *TINY, *paths]
    plain = run(compose_train(base), tmp_path / "plain")
    aligned = run(compose_train([*base, "recipe.align=coral", "recipe.align_stats=other_real"]), tmp_path / "al")
    assert "alignment" not in plain and aligned["alignment"]["stats_from"] == "other_real"
    assert aligned["alignment"]["transductive"] is False and aligned["history"] == plain["history"]
    p0, p1 = (np.load(tmp_path / d / "scores.npz")["probs"] for d in ("plain", "al"))
    assert p0.shape == p1.shape and not np.allclose(p0, p1)
    assert (tmp_path / "plain" / "checkpoint.pt").read_bytes() == (tmp_path / "al" / "checkpoint.pt").read_bytes()
    # C-to-B: the other real set is its training set, so an inductive alignment has nothing to read
    with pytest.raises(ValueError, match="align_stats=other_real has no other real set"):
        run(compose_train([*base, "experiment=C-to-B", "recipe.align=meanstd"]), tmp_path / "cb")


def test_also_aligned_scores_the_same_models_as_their_own_aligned_training(train_sets, tmp_path):
    """One training of seeds [0, 1], scored on Silicone and (A-to-C) on Meat, plain and under two alignments:
    every aligned run is byte for byte the run its own training with that recipe gives, and all share one history."""
    from palpation.apps.train import run

    paths = [f"data.{k}={v}" for k, v in train_sets.items()]
    base = ["experiment=A-to-B", "model=compact", "seeds=[0,1]", "clip_len=3", "track=false", "also_test=[A-to-C:meat]",
            *TINY, *paths]
    root = tmp_path / "shared"
    entries = [f"coral:other_real:{tmp_path / 'coral'}", f"meanstd:test_set:{tmp_path / 'seqless'}"]
    out = run(compose_train([*base, f"also_aligned=[{','.join(entries)}]"]), root / "A-to-B" / "L3")
    assert len(out) == 2 * 2 * 3  # seeds x test sets x (plain, two alignments)
    alone = tmp_path / "alone"
    run(compose_train([*base, "recipe.align=coral", "recipe.align_stats=other_real"]), alone / "A-to-B" / "L3")
    for config in ("A-to-B", "A-to-C"):
        for seed in (0, 1):
            runs = {k: tmp_path / k / config / "L3" / f"seed{seed}" for k in ("shared", "coral", "seqless", "alone")}
            m = {k: json.loads((d / "metrics.json").read_text()) for k, d in runs.items()}
            assert m["shared"]["history"] == m["coral"]["history"] == m["seqless"]["history"] == m["alone"]["history"]
            assert "alignment" not in m["shared"] and m["seqless"]["alignment"]["transductive"] is True
            assert m["coral"]["alignment"] == m["alone"]["alignment"]
            same = np.load(runs["coral"] / "scores.npz")["probs"], np.load(runs["alone"] / "scores.npz")["probs"]
            assert np.array_equal(*same)
            plain = np.load(runs["shared"] / "scores.npz")["probs"]
            assert not np.allclose(plain, same[0]) and not np.allclose(plain, np.load(runs["seqless"] / "scores.npz")["probs"])
    bad = [("also_aligned=[coral:other_real]", "write '<align>:<align_stats>:<folder>'"),
           (f"also_aligned=[none:test_set:{tmp_path}]", "write '<align>:<align_stats>:<folder>'"),
           (f"also_aligned=[coral:a:{tmp_path}]", "write '<align>:<align_stats>:<folder>'"),
           (f"also_aligned=[coral:test_set:{tmp_path / 'x'},meanstd:test_set:{tmp_path / 'x'}]", "distinct folders")]
    for override, message in bad:
        with pytest.raises(ValueError, match=message):
            run(compose_train([*base, override]), tmp_path / "bad" / "A-to-B" / "L3")
    with pytest.raises(ValueError, match="also_aligned uses the models of `seeds`"):
        run(compose_train(["experiment=A-to-B", f"also_aligned=[coral:test_set:{tmp_path}]", "track=false"]), tmp_path)


def test_select_on_other_real_chooses_on_the_other_set_and_never_on_the_scored_one(train_sets, tmp_path):
    from palpation.apps.train import run

    paths = [f"data.{k}={v}" for k, v in train_sets.items()]
    base = ["model=compact", "seed=0", "clip_len=3", "track=false", *TINY, *paths, "recipe.select_on=other_real"]
    m = run(compose_train(["experiment=A-to-B", *base]), tmp_path / "ab")
    assert m["selected_on"] == "meat all"
    ref = json.loads(json.dumps(run(compose_train(["experiment=A-to-B", *base[:-1]]), tmp_path / "ref")))
    assert "selected_on" not in ref and ref["history"] != m["history"]  # val scores from another set
    cb = run(compose_train(["experiment=C-to-B", *base]), tmp_path / "cb")
    assert cb["selected_on"] == "meat val"  # the Meat-trained model's other real set is its own val trials
    with pytest.raises(ValueError, match="the set it is scored on"):
        run(compose_train(["experiment=A-to-B", "seeds=[0]", "also_test=[A-to-C:meat]", *base]),
            tmp_path / "x" / "A-to-B" / "L3")
