"""Rebuilding the scored central frames from the window rule, and the alignment checks."""

import numpy as np
import pytest

from palpation.mapping.samples import align, central_frames, load_scores
from palpation.mapping.rescore import dense_windows


def test_silicone_central_frames_are_2_to_13():
    seq, frame = central_frames([16] * 10, 5, 1)
    assert len(seq) == 120
    assert frame[:12].tolist() == list(range(2, 14)) and (seq[:12] == 0).all() and seq[-1] == 9


def test_meat_and_sim_central_frames():
    seq, frame = central_frames([22, 21], 5, 1, window="centred")  # Meat: one window per stored frame
    assert len(seq) == 22 + 21 and frame[0] == 0 and frame[-1] == 20
    seq, frame = central_frames([22, 21], 5, 1)
    assert len(seq) == 18 + 17 and frame[0] == 2 and frame[-1] == 18
    seq, frame = central_frames([317], 5, 24)
    assert frame.tolist() == [48, 72, 96, 120, 144, 168, 192, 216, 240]  # 9 windows, starts 0..192


def test_dense_slide_windows():
    w = dense_windows([317], 5)
    assert len(w) == 317 - 24 * 5 + 1 and w[-1, 1] == 197  # every start s = 0 .. n - 24 L


def _sequences(rng, n=3, T=8):
    markers = [rng.uniform(800, 1200, (T, 127, 2)) for _ in range(n)]
    labels = [(rng.random((T, 127)) < 0.2).astype(np.int8) for _ in range(n)]
    return markers, labels


def test_align_picks_the_central_frames():
    rng = np.random.default_rng(0)
    markers, labels = _sequences(rng)
    seq, frame = central_frames([8] * 3, 5, 1)
    lab = np.concatenate([labels[s][f] for s, f in zip(seq, frame)])
    probs = rng.random(lab.size).astype(np.float32)
    s = align(probs, lab, markers, labels, 5, 1)
    assert len(s) == 12 and np.array_equal(s.pixels[5], markers[seq[5]][frame[5]])
    assert np.array_equal(s.probs.ravel(), probs)


def test_align_rejects_wrong_lengths_and_mismatched_labels():
    rng = np.random.default_rng(1)
    markers, labels = _sequences(rng)
    seq, frame = central_frames([8] * 3, 5, 1)
    lab = np.concatenate([labels[s][f] for s, f in zip(seq, frame)])
    with pytest.raises(ValueError, match="central frames x 127"):
        align(np.zeros(lab.size - 127), lab[:-127], markers, labels, 5, 1, "A-to-B")
    with pytest.raises(ValueError, match="central frames x 127"):  # scored at L = 3
        align(np.zeros(lab.size), lab, markers, labels, 3, 1)
    with pytest.raises(ValueError, match="labels differ"):
        align(np.zeros(lab.size), 1 - lab, markers, labels, 5, 1)
    with pytest.raises(ValueError, match="empty prediction set"):
        align(np.zeros(0), np.zeros(0), markers, labels, 5, 1)


def test_load_scores_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="train rule"):
        load_scores(tmp_path / "missing.npz")
    np.savez(tmp_path / "empty.npz", probs=np.zeros(0), labels=np.zeros(0))
    with pytest.raises(ValueError, match="empty prediction set"):
        load_scores(tmp_path / "empty.npz")
    np.savez(tmp_path / "bad.npz", probs=np.zeros(3))
    with pytest.raises(ValueError, match="missing"):
        load_scores(tmp_path / "bad.npz")
