"""The operating-point rule on hand-made maps (SPEC §12)."""

import numpy as np
import pytest

from palpation.mapping.threshold import RULE_FALLBACK, RULE_PRECISION, choose_threshold, grow, tolerance_curve


def ranked_line(n_true=30, n_false=10, gap_px=8):
    """Truth: row 5, cols 0..n_true-1 scored 0.9 down to 0.6 (all hits). False positives far away at
    row 5 + gap, cols 0..n_false-1, with scores interleaved below 0.75."""
    shape = (20, max(n_true, n_false) + 5)
    truth = np.zeros(shape, bool)
    truth[5, :n_true] = True
    score = np.full(shape, -1.0, np.float32)
    score[5, :n_true] = np.linspace(0.9, 0.6, n_true)
    score[5 + gap_px, :n_false] = np.linspace(0.74, 0.55, n_false)
    return score, score > -1, truth


def test_grow_is_an_l2_disc():
    t = np.zeros((9, 9), bool)
    t[4, 4] = True
    g = grow(t, 3)
    assert g.sum() == 29  # lattice points with x^2 + y^2 <= 9
    assert g[4, 7] and not g[7, 7]
    assert grow(np.zeros((3, 3), bool), 3).sum() == 0  # no truth: nothing grows


def test_curve_counts_distinct_scores():
    score, visited, truth = ranked_line()
    c = tolerance_curve(score, visited, truth, 3.0)
    assert np.all(np.diff(c["threshold"]) < 0)
    assert c["n_pred"][-1] == visited.sum()
    assert c["precision"][0] == 1.0
    assert c["n_true_grown"] == grow(truth, 3).sum()


def test_max_recall_with_precision_at_least_0_9():
    score, visited, truth = ranked_line()
    op, curve = choose_threshold(score, visited, truth)
    assert op.rule == RULE_PRECISION
    assert op.precision >= 0.9 and op.n_pred >= 20
    ok = (curve["precision"] >= 0.9) & (curve["n_pred"] >= 20)
    assert op.recall == pytest.approx(curve["recall"][ok].max())
    # one more candidate would break the precision target
    below = curve["threshold"] < op.threshold
    assert not ok[below].any()


def test_fewer_than_min_pixels_falls_back_to_f1():
    score, visited, truth = ranked_line(n_true=10, n_false=0)
    op, _ = choose_threshold(score, visited, truth)  # precision 1 but only 10 predicted pixels
    assert op.rule == RULE_FALLBACK
    op5, _ = choose_threshold(score, visited, truth, min_pixels=5)
    assert op5.rule == RULE_PRECISION and op5.threshold == pytest.approx(0.6)


def test_tolerance_counts_near_misses_as_hits():
    score, visited, truth = ranked_line(n_true=25, n_false=0)
    shifted = np.roll(score, 2, axis=0)  # predictions 2 px off the truth
    op, _ = choose_threshold(shifted, shifted > -1, truth, tolerance_mm=3.0)
    assert op.rule == RULE_PRECISION and op.precision == 1.0
    op0, _ = choose_threshold(shifted, shifted > -1, truth, tolerance_mm=0.0)
    assert op0.rule == RULE_FALLBACK


def test_ties_prefer_precision_then_the_higher_threshold():
    truth = np.zeros((10, 40), bool)
    truth[2, :] = True
    score = np.full(truth.shape, -1.0)
    score[2, :30] = 0.8
    score[2, 30:] = 0.7  # lowers the threshold and raises recall: chosen
    score[9, :3] = 0.65  # a few far misses: recall unchanged, precision lower -> not chosen
    op, _ = choose_threshold(score, score > -1, truth)
    assert op.threshold == pytest.approx(0.7) and op.recall == pytest.approx(40 / grow(truth, 3).sum())


def test_nothing_visited_is_a_clear_error():
    z = np.zeros((4, 4))
    with pytest.raises(ValueError, match="no visited pixel"):
        choose_threshold(z - 1, z > 0, z > 0)
