"""Calibration on toy sets with known miscalibration (issue 15)."""

import numpy as np
import pytest

from palpation.metrics.calibration import Calibrator, ece, fit_calibrator, logit, positive_share, reliability


@pytest.fixture(scope="module")
def toy():
    """True logit z; the 'model' reports sigmoid(3 z + 4): overconfident and shifted toward positive."""
    rng = np.random.default_rng(0)
    z = rng.normal(-2.0, 2.0, 40_000)
    y = (rng.random(z.size) < 1 / (1 + np.exp(-z))).astype(np.int8)
    return 1 / (1 + np.exp(-(3 * z + 4))), y, 1 / (1 + np.exp(-z))


def test_platt_recovers_the_known_distortion(toy):
    over, y, true = toy
    cal = fit_calibrator(over[::2], y[::2], "platt")  # fit on one half, measure on the other
    assert cal.scale == pytest.approx(1 / 3, rel=0.05) and cal.shift == pytest.approx(-4 / 3, rel=0.05)
    assert ece(over[1::2], y[1::2]) > 0.15 and ece(cal.apply(over[1::2]), y[1::2]) < 0.015
    assert positive_share(cal.apply(over)) == pytest.approx(positive_share(true), abs=0.01)


def test_temperature_fixes_pure_overconfidence_and_keeps_the_ranking():
    rng = np.random.default_rng(1)
    z = rng.normal(0.0, 1.5, 40_000)
    y = (rng.random(z.size) < 1 / (1 + np.exp(-z))).astype(np.int8)
    over = 1 / (1 + np.exp(-4 * z))  # temperature 1/4
    cal = fit_calibrator(over, y, "temperature")
    assert cal.scale == pytest.approx(0.25, rel=0.05) and cal.shift == 0.0
    assert ece(over, y) > 0.08 and ece(cal.apply(over), y) < 0.01
    order = np.argsort(over, kind="stable")
    assert np.all(np.diff(cal.apply(over)[order]) >= 0)  # monotone: AUROC and AP are unchanged


def test_ece_and_reliability_on_known_bins():
    probs = np.array([0.05, 0.05, 0.95, 0.95])
    labels = np.array([0, 0, 1, 0])
    r = reliability(probs, labels, n_bins=10)
    assert r["count"].tolist() == [2, 0, 0, 0, 0, 0, 0, 0, 0, 2]
    assert ece(probs, labels, n_bins=10) == pytest.approx(0.5 * 0.05 + 0.5 * 0.45)
    assert ece(np.full(4, 0.5), np.array([0, 1, 0, 1])) == 0.0  # calibrated on average


def test_identity_and_errors():
    p = np.array([0.2, 0.7], np.float32)
    assert np.array_equal(Calibrator().apply(p), p) and np.allclose(logit([0.5]), 0.0)
    with pytest.raises(ValueError, match="both classes"):
        fit_calibrator(p, np.zeros(2), "platt")
    with pytest.raises(ValueError, match="unknown calibration"):
        fit_calibrator(p, np.array([0, 1]), "isotonic")


def test_cross_fit_never_reads_a_sets_own_labels(toy):
    """Each set is calibrated on its partner: a set's own labels (even all flipped) leave its calibrator as it
    was, its partner's labels change it; a set named as its own partner is refused."""
    from palpation.metrics.calibration import cross_fit

    over, y, _ = toy
    a, b = (over[:20_000], y[:20_000]), (over[20_000:], y[20_000:])
    pairs = {"a": "b", "b": "a"}
    cals = cross_fit({"a": a, "b": b}, pairs)
    flipped = cross_fit({"a": (a[0], 1 - a[1]), "b": b}, pairs)
    assert flipped["a"] == cals["a"]  # a's labels changed nothing of a's calibration
    assert flipped["b"] != cals["b"]  # they are b's calibration data
    assert cals["a"] == fit_calibrator(*b, "platt")
    assert cross_fit({"a": a}, {"a": None}) == {"a": None}
    with pytest.raises(ValueError, match="its own partner"):
        cross_fit({"a": a}, {"a": "a"})
    with pytest.raises(ValueError, match="has no scores"):
        cross_fit({"a": a}, {"a": "c"})


def test_brier_known_values():
    from palpation.metrics.calibration import brier

    assert brier([1.0, 0.0, 0.5, 0.5], [1, 0, 1, 0]) == pytest.approx(0.125)
    with pytest.raises(ValueError, match="matching"):
        brier([0.1], [1, 0])


def test_shift_recovers_a_pure_prior_shift():
    rng = np.random.default_rng(3)
    z = rng.normal(-2.0, 2.0, 40_000)
    y = (rng.random(z.size) < 1 / (1 + np.exp(-z))).astype(np.int8)
    cal = fit_calibrator(1 / (1 + np.exp(-(z + 1.5))), y, "shift")  # scores 1.5 logits too high
    assert cal.method == "shift" and cal.scale == 1.0 and cal.shift == pytest.approx(-1.5, abs=0.05)
