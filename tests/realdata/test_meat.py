"""Meat set: trial table, similarity fit and order on synthetic panels, bad input, the real build."""

import json

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from palpation.markers.lattice import ideal_hex_lattice
from palpation.markers.order import apply_similarity
from palpation.paths import REPO_ROOT
from palpation.realdata.meat import (
    N_STATES,
    TRIALS,
    align_states,
    build_meat,
    scope_groups,
    similarity_params,
    state_to_trial,
    trial_sequences,
)
from palpation.realdata.panels import PanelDots

TEMPLATE = ideal_hex_lattice(55.0, 0.0, (1040.0, 584.0))


def similarity(scale, angle_deg, t):
    a = np.radians(angle_deg)
    return np.hstack([scale * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]),
                      np.asarray(t, float)[:, None]])


# panel -> sensor, close to the viewer's (2.4 sensor px per panel px, no roll)
TRUE = similarity(2.4, 0.8, (551.0, 99.0))
TO_PANEL = np.vstack([TRUE, [0, 0, 1]])


def synthetic_panels(rng, n_states=N_STATES, noise_px=1.0):
    """Panel dots of a lightly deformed template, shuffled per state; label 1 on a vertical band."""
    inv = np.linalg.inv(TO_PANEL)[:2]
    truth, perms = [], []
    for _ in range(n_states):
        sensor = TEMPLATE + rng.normal(0, noise_px, TEMPLATE.shape)
        perm = rng.permutation(len(TEMPLATE))
        labels = (np.abs(TEMPLATE[:, 0] - 1000) < 30).astype(np.int8)
        truth.append(PanelDots(xy=apply_similarity(inv, sensor)[perm], labels=labels[perm]))
        perms.append(perm)
    return truth, perms


def test_trials_cover_every_state_once():
    states = np.concatenate([list(t.states) for t in TRIALS])
    np.testing.assert_array_equal(states, np.arange(N_STATES))
    assert [t.n_states for t in TRIALS] == [22, 21] + [22] * 8
    assert {t.trial_id for t in TRIALS if t.split == "val"} == {5, 7, 9}  # 6 steaks, silicone, 3 straws


@pytest.mark.parametrize("state, trial_id, frame", [(0, 1, 2), (21, 1, 23), (22, 2, 2), (42, 2, 22),
                                                    (43, 3, 2), (130, 6, 23), (218, 10, 23)])
def test_state_to_trial(state, trial_id, frame):
    trial, f = state_to_trial(state)
    assert (trial.trial_id, f) == (trial_id, frame)


def test_state_to_trial_out_of_range():
    with pytest.raises(ValueError, match="219"):
        state_to_trial(219)


def test_similarity_fit_recovers_known_similarity():
    rng = np.random.default_rng(0)
    truth, perms = synthetic_panels(rng, n_states=5)
    xy = np.stack([d.xy for d in truth])
    idx, matrices = align_states(xy, TEMPLATE, [np.arange(5)])
    for s, perm in enumerate(perms):
        np.testing.assert_array_equal(perm[idx[s]], np.arange(len(TEMPLATE)))  # back in template order
    got, want = similarity_params(matrices[0]), similarity_params(TRUE)
    assert got["scale"] == pytest.approx(want["scale"], rel=1e-3)
    assert got["rotation_deg"] == pytest.approx(want["rotation_deg"], abs=0.02)
    assert got["tx"] == pytest.approx(want["tx"], abs=1.0) and got["ty"] == pytest.approx(want["ty"], abs=1.0)


@pytest.mark.parametrize("scope, n_groups", [("video", 1), ("trial", 10), ("state", 219)])
def test_scope_groups(scope, n_groups):
    groups = scope_groups(scope)
    assert len(groups) == n_groups
    np.testing.assert_array_equal(np.sort(np.concatenate(groups)), np.arange(N_STATES))


def test_build_meat_on_synthetic_panels():
    truth, _ = synthetic_panels(np.random.default_rng(1))
    hard = [PanelDots(xy=d.xy + 0.5, labels=1 - d.labels) for d in truth]
    data = build_meat(truth, hard, TEMPLATE, scope="trial", source="synthetic.mp4")
    assert data["markers"].shape == (N_STATES, 127, 2)
    np.testing.assert_allclose(data["markers"], np.broadcast_to(TEMPLATE, data["markers"].shape), atol=6)
    band = (np.abs(TEMPLATE[:, 0] - 1000) < 30).astype(np.int32)
    np.testing.assert_array_equal(data["labels"], np.broadcast_to(band, data["labels"].shape))
    np.testing.assert_array_equal(data["ref_hard_pred"], 1 - data["labels"])
    seqs = trial_sequences(data)
    assert [len(s["markers"]) for s in seqs] == [t.n_states for t in TRIALS]
    assert seqs[1]["frame"].tolist() == list(range(2, 23))


def test_state_with_missing_dot_names_file_and_state():
    truth, _ = synthetic_panels(np.random.default_rng(2))
    truth[57] = PanelDots(xy=truth[57].xy[:126], labels=truth[57].labels[:126])
    with pytest.raises(ValueError, match=r"meat_video\.mp4: state 57 .*126 dots"):
        build_meat(truth, truth, TEMPLATE, source="meat_video.mp4")


def test_misplaced_hard_panel_is_rejected():
    truth, _ = synthetic_panels(np.random.default_rng(3))
    hard = [PanelDots(xy=d.xy + 10.0, labels=d.labels) for d in truth]
    with pytest.raises(ValueError, match="state 0"):
        build_meat(truth, hard, TEMPLATE, source="v.mp4")


def test_panel_that_does_not_fit_the_template_is_rejected():
    """Dots that are no marker lattice (a wrong crop, say) fail loudly instead of being forced in."""
    rng = np.random.default_rng(4)
    truth = [PanelDots(xy=rng.uniform(0, 400, (127, 2)), labels=np.zeros(127, np.int8))
             for _ in range(N_STATES)]
    with pytest.raises(ValueError, match="does not match the template"):
        build_meat(truth, truth, TEMPLATE, source="v.mp4")


def test_meat_app_on_the_real_video(tmp_path, results_tmp):
    """The whole stage on the shipped video (~5 s): SPEC §13.5 counts, splits, outputs."""
    from palpation.apps.meat import run

    video = REPO_ROOT / "data/reference/videos/predictions_sim_to_meat.mp4"
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose("meat", overrides=[f"out.dir={tmp_path}", "track=false", f"video={video}"])
    meta = run(cfg)
    assert (meta["positives"], meta["nodes"]) == (1810, 27813)
    assert meta["states_without_positives"] == 90 and meta["max_positives_per_state"] == 38
    assert meta["splits"] == {"train": [1, 2, 3, 4, 6, 8, 10], "val": [5, 7, 9]}
    assert meta["fit_residual_px"]["median"] < 8.0
    with np.load(tmp_path / "meat.npz") as npz:
        assert npz["markers"].shape == (219, 127, 2) and npz["ref_hard_pred"].shape == (219, 127)
    assert json.loads((tmp_path / "meat.json").read_text())["trials"][1]["n_frames"] == 21
    assert (tmp_path / "meat_overview.png").is_file() and (tmp_path / "meat_overview.pdf").is_file()
