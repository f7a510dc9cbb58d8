"""Per-pixel statistics and d-bar on hand-made grids."""

import numpy as np
import pytest

from palpation.mapping.stats import all_radii, map_stats, nearest_truth_mm, scores_from_counts


def line_maps(offset_px: int, shape=(20, 30)):
    """Truth: row 10, cols 5..24. Prediction: the same columns `offset_px` rows lower (score 0.9)."""
    truth = np.zeros(shape, bool)
    truth[10, 5:25] = True
    score = np.full(shape, 0.1, np.float32)
    score[10 + offset_px, 5:25] = 0.9
    return score, np.ones(shape, bool), truth


def test_offset_line_gives_dbar_equal_to_the_offset():
    for offset in (0, 1, 2, 5):
        score, visited, truth = line_maps(offset)
        s = map_stats(score, visited, truth, 0.5)
        assert s["distance_mm"]["mean"] == pytest.approx(offset)
        assert s["distance_mm"]["n"] == 20


def test_counts_and_scores_exact_pixels():
    score, visited, truth = line_maps(2)
    s = map_stats(score, visited, truth, 0.5)
    assert (s["tp"], s["fp"], s["fn"], s["tn"]) == (0, 20, 20, 600 - 40)
    assert s["precision"] == 0 and s["recall"] == 0 and s["mcc"] < 0
    # grown by 2 px the shifted line is inside the truth band: all predictions count
    s2 = map_stats(score, visited, truth, 0.5, radius_px=2)
    assert s2["fp"] == 0 and s2["tp"] == 20 and s2["distance_mm"]["mean"] == 0
    radii = all_radii(score, visited, truth, 0.5)
    assert radii["d_bar_mm"] == pytest.approx(2.0)
    assert set(radii) == {"r0", "r1", "r2", "d_bar_mm"}


def test_diagonal_distance_is_euclidean():
    truth = np.zeros((10, 10), bool)
    truth[2, 2] = True
    pred = np.zeros_like(truth)
    pred[5, 6] = True
    d, orphans = nearest_truth_mm(pred, truth)
    assert d.tolist() == [5.0] and orphans == 0


def test_unvisited_pixels_are_never_predicted_and_score_minus_one_in_ap():
    score, visited, truth = line_maps(0)
    visited[:, :10] = False
    score[~visited] = -1
    s = map_stats(score, visited, truth, 0.5)
    assert s["tp"] == 15 and s["fn"] == 5  # the 5 unvisited truth pixels are misses
    assert 0 < s["ap"] < 1


def test_maps_without_truth_give_no_distance():
    score, visited, truth = line_maps(1)
    stack_score = np.stack([score, score])
    stack_truth = np.stack([truth, np.zeros_like(truth)])
    s = map_stats(stack_score, np.stack([visited, visited]), stack_truth, 0.5)
    assert s["distance_mm"]["n"] == 20 and s["distance_mm"]["n_pred_without_truth"] == 20
    assert s["distance_mm"]["mean"] == pytest.approx(1.0)
    assert s["tp"] + s["fp"] + s["fn"] + s["tn"] == 2 * 600  # counts summed over maps


def test_mcc_iou_conventions():
    c = {"tp": 0, "fp": 0, "fn": 0, "tn": 10}
    s = scores_from_counts(c)
    assert s["mcc"] == 0 and s["fg_iou"] == 1.0 and s["bg_iou"] == 1.0


def test_shape_mismatch_is_an_error():
    score, visited, truth = line_maps(0)
    with pytest.raises(ValueError, match="differ in shape"):
        map_stats(score, visited, truth[:5], 0.5)
