"""Corrupt inputs of every reader: one line naming the file and the fix, never a raw traceback."""

import json

import cv2
import numpy as np
import pytest
import torch

from palpation.graph.layout import rest_layout
from palpation.graph.sources import load_meat, load_silicone
from palpation.graph.synthetic import write_meat, write_silicone
from palpation.measured import load_measured_set, make_measured_set, save_measured_set, MeasuredState

REST = rest_layout("ideal")


def truncate(path, keep: int = 300):
    path.write_bytes(path.read_bytes()[:keep])
    return path


@pytest.fixture
def measured(tmp_path):
    states = [MeasuredState("rest", "rest.png", "rest", 0.0), MeasuredState("press_2", "p.jpg", "press", 2.0)]
    mset = make_measured_set(np.stack([REST, REST + 1]), np.ones((2, 127), bool), REST, states)
    return save_measured_set(tmp_path / "flat_tip", mset)[0]


def test_measured_set_truncated(measured, fault):
    """a truncated measured-set npz (was a raw zipfile.BadZipFile)"""
    truncate(measured)
    with fault(ValueError, str(measured), "not a readable npz archive", "save_measured_set"):
        load_measured_set(measured)


def test_measured_set_not_a_zip(measured, fault):
    """a measured-set npz that is not an archive at all"""
    measured.write_bytes(b"PK\x03\x04 and then nonsense")
    with fault(ValueError, str(measured), "re-save it"):
        load_measured_set(measured)


def test_measured_set_json_corrupt(measured, fault):
    """the measured set's JSON half cut short"""
    meta = measured.with_suffix(".json")
    meta.write_text(meta.read_text()[:40])
    with fault(ValueError, str(meta), "not valid JSON", "fix or re-save it"):
        load_measured_set(measured)


def _checkpoint(path, seed: int = 0):
    from palpation.graph.normalise import NormStats
    from palpation.model.checkpoint import save_checkpoint
    from palpation.model.config import ModelConfig
    from palpation.model.stgnn import STGNN

    cfg = ModelConfig("compact", 56, 64, 32)
    torch.manual_seed(seed)
    stats = NormStats((0.0,), (1.0,), (0.0,), (1.0,), (0.0,), (1.0,), 0.9, 4, "sample")
    save_checkpoint(path, STGNN(3, cfg), cfg, stats, REST)
    return path


def test_checkpoint_bytes_identical_for_the_same_seed(tmp_path):
    """the same seed gives the same checkpoint.pt bytes (the temporary name stays out of the zip)"""
    a = _checkpoint(tmp_path / "a" / "checkpoint.pt")
    b = _checkpoint(tmp_path / "b" / "checkpoint.pt")
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes() != _checkpoint(tmp_path / "c" / "checkpoint.pt", seed=1).read_bytes()


def test_checkpoint_truncated(tmp_path, fault):
    """a checkpoint.pt cut short"""
    from palpation.model.checkpoint import load_checkpoint

    path = truncate(_checkpoint(tmp_path / "checkpoint.pt"), 5000)
    with fault(ValueError, str(path), "damaged or truncated", "rerun its train rule"):
        load_checkpoint(path)


def test_checkpoint_of_something_else(tmp_path, fault):
    """a torch file that is not a palpation checkpoint"""
    from palpation.model.checkpoint import load_checkpoint

    path = tmp_path / "checkpoint.pt"
    torch.save([1, 2], path)
    with fault(ValueError, str(path), "not a palpation ST-GNN checkpoint", "rerun its train rule"):
        load_checkpoint(path)


def test_scores_truncated(tmp_path, fault):
    """a truncated scores.npz read by the training tables and the maps"""
    from palpation.metrics.scores import load_scores

    path = tmp_path / "scores.npz"
    np.savez_compressed(path, probs=np.random.default_rng(0).random(500), labels=np.zeros(500, np.int8))
    truncate(path)
    with fault(ValueError, str(path), "not a readable npz", "rerun the train rule"):
        load_scores(path)


def test_scores_missing_labels(tmp_path, fault):
    """a scores.npz without `labels`"""
    from palpation.metrics.scores import load_scores

    path = tmp_path / "scores.npz"
    np.savez(path, probs=np.zeros(4))
    with fault(ValueError, str(path), "['labels']", "rerun the train rule"):
        load_scores(path)


def test_metrics_json_truncated(tmp_path, fault):
    """a truncated metrics.json read by the training report"""
    from palpation.report.runs import load_runs, run_dir

    path = run_dir(tmp_path, "A-to-B", 5, 0) / "metrics.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps({"test": {"ap": 0.5}})[:9])
    with fault(ValueError, str(path), "not valid JSON", "rerun the train rule"):
        load_runs(tmp_path, ["A-to-B"], [5], [0])


def test_silicone_set_truncated(tmp_path, fault):
    """a truncated Silicone set"""
    path = truncate(write_silicone(tmp_path / "silicone.npz", REST, n_videos=2, n_frames=6))
    with fault(ValueError, str(path), "silicone_set rule"):
        load_silicone(path)


def test_meat_set_with_nan_markers(tmp_path, fault):
    """a NaN marker in a Meat clip"""
    path = write_meat(tmp_path / "meat.npz", REST, n_frames=(6,) * 4, n_val=1)
    with np.load(path) as z:
        arrays = dict(z)
    arrays["markers"][3, 0, 1] = np.inf
    np.savez(path, **arrays)
    with fault(ValueError, str(path), "`markers` holds 1 NaN/inf", "meat_set rule"):
        load_meat(path, "train")


def test_small_photo(tmp_path, fault):
    """a photo smaller than the sensor circle (was a cv2 assertion)"""
    from palpation.markers.detect import RatioDetector
    from palpation.markers.photoset import order_photo

    path = tmp_path / "press_press_depth=2_angle=10.jpg"
    cv2.imwrite(str(path), np.full((40, 60), 128, np.uint8))
    with fault(ValueError, str(path), "60x40 px", "sensor circle", "detector.circle_centre_px"):
        order_photo(path, REST, RatioDetector())


def test_photo_not_an_image(tmp_path, fault):
    """a photo file that is not an image"""
    from palpation.markers.detect import load_gray

    path = tmp_path / "sensor_default_state.png"
    path.write_bytes(b"not a png")
    with fault(ValueError, str(path), "not an image file"):
        load_gray(path)


def test_video_corrupt(tmp_path, fault):
    """an mp4 that OpenCV cannot decode"""
    from palpation.realdata.video import frame_count

    path = tmp_path / "dataset_annotations_silicone.mp4"
    path.write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"\x00" * 64)
    with fault(ValueError, str(path), "cannot be decoded"):
        frame_count(path)


def test_frame_time_too_large(fault):
    """a frame time (twin.integrator.dt x substeps) far too large for the controller"""
    from palpation.twin.trajectory import plan_trajectory

    with fault(ValueError, "0.5 s", "twin.integrator.dt", "not reached"):
        plan_trajectory("press", frame_dt_s=0.5)
