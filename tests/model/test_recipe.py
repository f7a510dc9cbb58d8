"""The robust recipe's switches (issue 15): each changes what it says and nothing else; reference unchanged."""

import dataclasses

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from palpation.apps.train import job_from_config
from palpation.graph.augment import draw_rotations
from palpation.graph.clips import ClipSet
from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.layout import rest_layout
from palpation.graph.sources import load_dataset
from palpation.graph.synthetic import write_meat, write_sim
from palpation.model import ModelConfig, TrainConfig
from palpation.model.recipe import SWITCHES, switch_off
from palpation.model.train import fit, training_batch
from palpation.paths import REPO_ROOT

COMPACT = ModelConfig("compact", 56, 64, 32)
OFF = TrainConfig(batch_size=4, epochs=1, train_batches=1, val_batches=1, rotation="none")


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    rest = rest_layout("ideal")
    root = tmp_path_factory.mktemp("recipe")
    sim = ClipSet(load_dataset("sim", write_sim(root / "sim", rest, n_traj=7, n_frames=72), "train"), 3, rest)
    meat_path = write_meat(root / "meat.npz", rest, n_frames=(8,) * 5, n_val=2)
    meat = {s: ClipSet(load_dataset("meat", meat_path, s), 3, rest) for s in ("train", "val")}
    return rest, sim, meat


def _batch(clips, cfg, seed=5, idx=(0, 1, 2, 3)):
    return training_batch(clips, np.array(idx), cfg, np.random.default_rng(seed))


def test_all_switches_off_is_the_reference_batch(sets):
    rest, sim, _ = sets
    ref = dataclasses.replace(OFF, rotation="reference")
    m, lab = _batch(sim, ref)
    rng = np.random.default_rng(5)  # the reference code path: one rotation draw, then gather
    m0, lab0 = sim.gather(np.arange(4), draw_rotations(rng, 4, "reference"), False)
    assert np.array_equal(m, m0) and np.array_equal(lab, lab0)


def test_jitter_adds_detector_noise_only(sets):
    _, sim, _ = sets
    m0, lab0 = _batch(sim, OFF)
    m, lab = _batch(sim, dataclasses.replace(OFF, jitter_px=0.2))
    d = (m - m0).astype(np.float64)
    assert np.array_equal(lab, lab0)  # the truth is not the measurement
    assert abs(d.std() - 0.2) < 0.01 and abs(d.mean()) < 0.01 and np.mean(d != 0) > 0.99


def test_dropout_holds_the_previous_frame(sets):
    _, sim, _ = sets
    m0, lab0 = _batch(sim, OFF)
    m, lab = _batch(sim, dataclasses.replace(OFF, marker_dropout=0.2))
    assert np.array_equal(lab, lab0) and np.array_equal(m[:, 0], m0[:, 0])  # frame 0 has no previous one
    changed = np.any(m != m0, axis=-1)  # (B, L, 127)
    assert 0.1 < changed[:, 1:].mean() < 0.3
    b, t, i = np.nonzero(changed)
    assert np.array_equal(m[b, t, i], m[b, t - 1, i])  # a dropped marker sits where it was a frame before


def test_displacement_scale_scales_about_the_rest_layout(sets):
    rest, sim, _ = sets
    m0, lab0 = _batch(sim, OFF)
    m, lab = _batch(sim, dataclasses.replace(OFF, displacement_scale=0.3))
    ratio = (m - rest) / np.where(np.abs(m0 - rest) > 1e-3, m0 - rest, np.nan)
    per_clip = np.nanmedian(ratio.reshape(4, -1), axis=1)
    assert np.all((0.7 <= per_clip) & (per_clip <= 1.3)) and np.ptp(per_clip) > 0.01
    assert np.allclose(m - rest, per_clip[:, None, None, None] * (m0 - rest), atol=1e-3)
    assert lab.shape == lab0.shape  # Sim labels are recomputed on the scaled markers (the label rule)


def test_early_stopping_and_selection_metric(sets):
    rest, _, meat = sets
    topo = clip_topology(spatial_edges(rest), 3)
    cfg = TrainConfig(batch_size=2, epochs=8, train_batches=1, val_batches=2)
    full = fit(meat["train"], meat["val"], rest, topo, COMPACT, cfg, seed=3)
    assert len(full.history) == 8
    stopped = fit(meat["train"], meat["val"], rest, topo, COMPACT, dataclasses.replace(cfg, patience=2), seed=3)
    n = len(stopped.history)
    assert n == min(8, stopped.best_epoch + 3) and stopped.history == full.history[:n]  # nothing else changes
    by_ap = fit(meat["train"], meat["val"], rest, topo, COMPACT, dataclasses.replace(cfg, select_metric="ap"),
                seed=3)
    aps = [h["val/ap"] for h in by_ap.history]
    assert by_ap.best_epoch == int(np.argmax(aps)) and by_ap.best_val_score == max(aps)
    assert [h["train/loss"] for h in by_ap.history] == [h["train/loss"] for h in full.history]


def _compose(overrides):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return job_from_config(compose(config_name="train", overrides=overrides)).train


def test_recipes_compose_and_switch_off_restores_one_reference_value():
    ref, robust = _compose(["experiment=A-to-B"]), _compose(["experiment=A-to-B", "recipe=robust"])
    assert (ref.jitter_px, ref.marker_dropout, ref.displacement_scale, ref.patience, ref.select_metric,
            ref.calibration) == (0.0, 0.0, 0.0, None, "fg_iou", "none")
    for name in SWITCHES:
        off = _compose(["experiment=A-to-B", "recipe=robust", *switch_off(name)])
        differs = {f.name for f in dataclasses.fields(TrainConfig)
                   if getattr(off, f.name) != getattr(robust, f.name)}
        assert differs == set(SWITCHES[name]), name  # only the switch's own fields move
        assert all(getattr(off, k) == getattr(ref, k) for k in SWITCHES[name])


def test_calibrated_recipe_is_the_reference_plus_platt_only():
    """recipe=calibrated (the quick profile's) trains exactly as the reference and only rescales scores."""
    ref, cal = _compose(["experiment=A-to-B"]), _compose(["experiment=A-to-B", "recipe=calibrated"])
    differs = {f.name for f in dataclasses.fields(TrainConfig) if getattr(cal, f.name) != getattr(ref, f.name)}
    assert differs == set(SWITCHES["calibration"]) and cal.calibration == "platt"


def test_quick_recipe_is_calibrated_plus_ap_selection_only():
    """recipe=quick (the quick profile's): calibrated, the checkpoint chosen by val AP; nothing else moves."""
    cal, quick = _compose(["experiment=C-to-B", "recipe=calibrated"]), _compose(["experiment=C-to-B", "recipe=quick"])
    differs = {f.name for f in dataclasses.fields(TrainConfig) if getattr(quick, f.name) != getattr(cal, f.name)}
    assert differs == set(SWITCHES["select_ap"]) and quick.select_metric == "ap"


def test_calibration_rescales_the_written_scores_only(train_sets, tmp_path):
    """calibration=platt: the same model (checkpoint bytes), scores = the fitted map of the raw ones."""
    from palpation.apps.train import run
    from palpation.metrics.calibration import Calibrator

    base = ["experiment=C-to-B", "seed=0", "clip_len=3", "graph.rest=ideal", "train.batch_size=4", "train.epochs=1",
            "train.train_batches=2", "train.val_batches=2", "track=false", "progress=false",
            *[f"data.{k}={v}" for k, v in train_sets.items()]]
    out = {}
    for cal in ("none", "platt"):
        with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
            cfg = compose(config_name="train", overrides=[*base, f"recipe.calibration={cal}"])
        out[cal] = (run(cfg, tmp_path / cal), np.load(tmp_path / cal / "scores.npz")["probs"])
    (m0, p0), (m1, p1) = out["none"], out["platt"]
    assert "calibration" not in m0 and "test_raw" not in m0  # the reference metrics.json keeps its keys
    assert (tmp_path / "none/checkpoint.pt").read_bytes() == (tmp_path / "platt/checkpoint.pt").read_bytes()
    cal = Calibrator(**m1["calibration"])
    assert cal.method == "platt" and np.allclose(p1, cal.apply(p0), atol=1e-6)
    assert m1["test_raw"] == m0["test"] and m1["test"]["auroc"] == pytest.approx(m0["test"]["auroc"], abs=1e-3)


def test_robust_recipe_same_seed_identical_on_the_cpu(sets):
    """Every switch on (their draws come from the seed's stream): a seed trains to the same weights twice, alone
    and with other seeds (model.stacked), and another seed differs."""
    import torch

    from palpation.model.stacked import fit_seeds

    rest, _, meat = sets
    topo = clip_topology(spatial_edges(rest), 3)
    robust = TrainConfig(batch_size=2, epochs=3, train_batches=2, val_batches=2, norm_stats="full",
                         rotation="consistent", jitter_px=0.2, marker_dropout=0.01, displacement_scale=0.3,
                         patience=1, select_metric="ap", calibration="platt")
    runs = [fit(meat["train"], meat["val"], rest, topo, COMPACT, robust, seed=s) for s in (4, 4, 5)]
    stacked = [fit_seeds(meat["train"], meat["val"], rest, topo, COMPACT, robust, [4, 5]) for _ in range(2)]

    def same(a, b):
        return a.history == b.history and all(torch.equal(x, y) for x, y in
                                               zip(a.model.state_dict().values(), b.model.state_dict().values()))

    assert same(runs[0], runs[1]) and not same(runs[0], runs[2])
    assert all(same(a, b) for a, b in zip(*stacked))
