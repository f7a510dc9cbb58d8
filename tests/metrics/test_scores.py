"""scores.npz: written with its (sequence, frame) ids, read back checked; old files fail in one line."""

import numpy as np
import pytest

from palpation.metrics.scores import Scores, load_scores, save_scores


def test_round_trip(tmp_path):
    s = Scores(np.linspace(0, 1, 254, dtype=np.float32), np.tile([0, 1], 127).astype(np.int8),
               np.array([0, 1]), np.array([2, 2]))
    save_scores(tmp_path / "scores.npz", s)
    back = load_scores(tmp_path / "scores.npz")
    for k in ("probs", "labels", "sequence", "frame"):
        assert np.array_equal(getattr(back, k), getattr(s, k))
    assert back.sequence.dtype == np.int64 and back.probs.dtype == np.float32


def test_load_scores_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="train rule"):
        load_scores(tmp_path / "missing.npz")
    np.savez(tmp_path / "empty.npz", probs=np.zeros(0), labels=np.zeros(0), sequence=np.zeros(0), frame=np.zeros(0))
    with pytest.raises(ValueError, match="empty prediction set"):
        load_scores(tmp_path / "empty.npz")
    np.savez(tmp_path / "bad.npz", probs=np.zeros(3))
    with pytest.raises(ValueError, match=r"bad.npz lacks the key\(s\) \['labels'\]; rerun the train rule"):
        load_scores(tmp_path / "bad.npz")
    np.savez(tmp_path / "old.npz", probs=np.zeros(127), labels=np.zeros(127))  # before the ids
    with pytest.raises(ValueError, match=r"old.npz: no \(sequence, frame\) ids .*rerun the train rule") as e:
        load_scores(tmp_path / "old.npz")
    assert "\n" not in str(e.value)
    np.savez(tmp_path / "short.npz", probs=np.zeros(254), labels=np.zeros(254), sequence=[0], frame=[2])
    with pytest.raises(ValueError, match="254 scores but 1 sequence"):
        load_scores(tmp_path / "short.npz")
