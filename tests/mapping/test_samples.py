"""Attaching scores to the central frames their ids name, and the alignment checks."""

import numpy as np
import pytest

from palpation.mapping.rescore import dense_windows
from palpation.mapping.samples import align


def test_dense_slide_windows():
    w = dense_windows([317], 5)
    assert len(w) == 317 - 24 * 5 + 1 and w[-1, 1] == 197  # every start s = 0 .. n - 24 L


def _sequences(rng, n=3, T=8):
    markers = [rng.uniform(800, 1200, (T, 127, 2)) for _ in range(n)]
    labels = [(rng.random((T, 127)) < 0.2).astype(np.int8) for _ in range(n)]
    return markers, labels


def _ids():
    """Central frames 2..5 of three 8-frame sequences at L = 5, d = 1."""
    return np.repeat(np.arange(3), 4), np.tile(np.arange(2, 6), 3)


def test_align_picks_the_frames_of_the_ids():
    rng = np.random.default_rng(0)
    markers, labels = _sequences(rng)
    seq, frame = _ids()
    lab = np.concatenate([labels[s][f] for s, f in zip(seq, frame)])
    probs = rng.random(lab.size).astype(np.float32)
    s = align(probs, lab, seq, frame, markers, labels)
    assert len(s) == 12 and np.array_equal(s.pixels[5], markers[seq[5]][frame[5]])
    assert np.array_equal(s.probs.ravel(), probs) and np.array_equal(s.frame, frame)


def test_align_rejects_wrong_lengths_ids_and_mismatched_labels():
    rng = np.random.default_rng(1)
    markers, labels = _sequences(rng)
    seq, frame = _ids()
    lab = np.concatenate([labels[s][f] for s, f in zip(seq, frame)])
    with pytest.raises(ValueError, match="A-to-B: 1397 scores for 12 sequence"):
        align(np.zeros(lab.size - 127), lab[:-127], seq, frame, markers, labels, "A-to-B")
    with pytest.raises(ValueError, match="outside the 3 test sequences .*sequence 3, frame 2"):
        align(np.zeros(lab.size), lab, seq + 1, frame, markers, labels)
    with pytest.raises(ValueError, match="outside"):
        align(np.zeros(lab.size), lab, seq, frame + 3, markers, labels)  # frame 8 of an 8-frame sequence
    with pytest.raises(ValueError, match="labels differ"):
        align(np.zeros(lab.size), 1 - lab, seq, frame, markers, labels)
    with pytest.raises(ValueError, match="empty prediction set"):
        align(np.zeros(0), np.zeros(0), seq[:0], frame[:0], markers, labels)
