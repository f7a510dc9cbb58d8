import numpy as np
import pytest

from palpation.metrics.aggregate import GRID, best_of_five, mean_curve, pr_curve, resample, summarise_seeds


def test_summary_uses_sample_std():
    s = summarise_seeds([1.0, 2.0, 3.0])
    assert s == {"mean": 2.0, "std": 1.0, "min": 1.0, "max": 3.0, "n": 3}
    assert np.isnan(summarise_seeds([0.5])["std"])


def test_best_of_five_by_ap_then_auroc():
    runs = [{"seed": 0, "ap": 0.3, "auroc": 0.9}, {"seed": 1, "ap": 0.4, "auroc": 0.7},
            {"seed": 2, "ap": 0.4, "auroc": 0.8}, {"seed": 3, "ap": 0.2, "auroc": 0.99}]
    assert best_of_five(runs)["seed"] == 2


def test_resample_keeps_max_y_per_duplicate_x():
    x = np.array([1.0, 0.5, 0.5, 0.0])
    y = np.array([0.2, 0.4, 0.8, 1.0])
    (out,) = resample(x, [y], np.array([0.0, 0.5, 0.75, 1.0]))
    assert out.tolist() == [1.0, 0.8, pytest.approx(0.5), 0.2]


def test_mean_curve_band_and_grid():
    c1 = {"recall": np.array([0.0, 1.0]), "precision": np.array([1.0, 0.2]), "threshold": np.array([1.0, 0.0])}
    c2 = {"recall": np.array([0.0, 1.0]), "precision": np.array([1.0, 0.4]), "threshold": np.array([1.0, 0.0])}
    m = mean_curve([c1, c2])
    assert np.array_equal(m["x"], GRID) and len(GRID) == 201
    assert m["mean"][-1] == pytest.approx(0.3) and m["std"][-1] == pytest.approx(np.std([0.2, 0.4], ddof=1))
    assert np.all(m["lower"] >= 0) and np.all(m["upper"] <= 1)
    assert m["threshold"][0] == 1.0


def test_pr_curve_has_one_threshold_per_point():
    c = pr_curve(np.array([0.1, 0.4, 0.35, 0.8]), np.array([0, 0, 1, 1]))
    assert len(c["threshold"]) == len(c["precision"]) == len(c["recall"])
