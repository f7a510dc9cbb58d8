"""The seed-ensemble pseudo-label filter keeps only the markers the seeds agree on."""

import numpy as np
import pytest

from palpation.metrics.scores import Scores
from palpation.model.pseudo_labels import agreed_labels, ensemble_pseudo_labels


def test_only_agreed_labels_are_kept():
    probs = np.array([[0.9, 0.1, 0.9, 0.55, 0.2, 0.8],
                      [0.8, 0.2, 0.1, 0.60, 0.3, 0.7],
                      [0.7, 0.3, 0.9, 0.52, 0.4, 0.6]])
    labels, keep = agreed_labels(probs)
    assert keep.tolist() == [True, True, False, True, True, True]  # marker 2: one seed says no
    assert labels[keep].tolist() == [1, 0, 1, 0, 1]
    _, keep = agreed_labels(probs, margin=0.15)  # every seed 0.15 from 0.5: markers 3, 4 (0.4), 5 (0.6) go
    assert keep.tolist() == [True, True, False, False, False, False]
    labels, keep = agreed_labels(probs, min_agree=2 / 3)  # two of three seeds suffice
    assert keep.all() and labels.tolist() == [1, 0, 1, 1, 0, 1]


def test_seeds_of_other_clips_and_bad_rules_are_refused():
    s = Scores(np.full(127, 0.9, np.float32), np.zeros(127, np.int8), np.zeros(1, np.int64), np.zeros(1, np.int64))
    moved = Scores(s.probs, s.labels, s.sequence, s.frame + 1)
    with pytest.raises(ValueError, match="different clips"):
        ensemble_pseudo_labels([s, moved])
    labels, keep = ensemble_pseudo_labels([s, s])
    assert keep.all() and labels.all()
    with pytest.raises(ValueError, match="at least 2 seeds"):
        agreed_labels(np.array([[0.9]]))
    with pytest.raises(ValueError, match="min_agree"):
        agreed_labels(np.ones((2, 3)) * 0.9, min_agree=0.5)
