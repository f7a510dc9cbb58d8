"""The app on the extracted real sets with label-derived scores (skipped until the data rules ran)."""

import json

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from palpation.apps.vessel_maps import run
from palpation.graph.clips import ClipSet
from palpation.graph.layout import rest_layout
from palpation.graph.sources import load_dataset
from palpation.mapping.sources import meat_trials
from palpation.metrics.scores import Scores, save_scores
from palpation.paths import REPO_ROOT



def noisy_scores(dataset, data, labels, path, seed):
    """Label-derived scores of the test set's windows (L = 5), with their ids, as the train app writes them."""
    seq, frame = ClipSet(load_dataset(dataset, data, "test"), 5, rest_layout("ideal")).central_frames()
    lab = np.concatenate([labels[s][f] for s, f in zip(seq, frame)]).astype(np.int8)
    rng = np.random.default_rng(seed)
    probs = np.clip(0.35 + 0.35 * lab + rng.normal(0, 0.15, lab.size), 0, 1).astype(np.float32)
    save_scores(path, Scores(probs, lab, seq, frame))


def test_silicone_and_meat_maps(tmp_path, real_sets):
    SILICONE, MEAT = real_sets["silicone"], real_sets["meat"]
    with np.load(SILICONE) as z:
        noisy_scores("silicone", SILICONE, list(z["labels"]), tmp_path / "sil.npz", 0)
    trials = meat_trials(MEAT)
    noisy_scores("meat", MEAT, [t["labels"] for t in trials], tmp_path / "meat.npz", 1)
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="vessel_maps", overrides=[
            "configs=[A-to-B,A-to-C]", f"scores.A-to-B={tmp_path / 'sil.npz'}",
            f"scores.A-to-C={tmp_path / 'meat.npz'}", f"data.silicone={SILICONE}", f"data.meat={MEAT}",
            f"out_dir={tmp_path / 'maps'}", "track=false"])
    result = run(cfg)
    sil, meat = result["configs"]["A-to-B"], result["configs"]["A-to-C"]
    assert sil["grid"]["rows"]["size_px"] == 100 and sil["dropped_samples"] == 0 and sil["n_samples"] == 120
    assert len(meat["maps"]) == 10 and meat["grid"]["rows"]["world"] == "x" and meat["n_samples"] == 219
    assert all(c["mean_mm"] < 3.5 for c in meat["meta"]["pose_check"].values())
    assert 0.15 < sil["photo"]["iou_video_photo"] < 0.5
    check = json.loads((tmp_path / "maps" / "silicone_pose_check.json").read_text())
    assert check["check"]["dots_to_photo_mm"]["mean"] < 1.0
    assert (tmp_path / "maps" / "A-to-B_photo_confusion_big.png").exists()
