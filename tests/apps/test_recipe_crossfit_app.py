"""Cross-fitted calibration between the real sets (palpation.apps.recipe_crossfit, issue 15): a test set's own
labels and own map never choose its calibration or its map threshold."""

from types import SimpleNamespace

import numpy as np
from palpation.apps.recipe_crossfit import map_at, same_model, seed_rows, to_raw
from palpation.metrics.calibration import Calibrator, fit_calibrator

STORED = {"method": "platt", "scale": 2.0, "shift": -1.0, "n_fit": 10}  # a Sim-val Platt both sets were written with


def _set(seed: int, shift: float, n: int = 4096):
    """Raw scores with a set-specific logit shift (the sim-to-real shift), labels drawn from the true logit."""
    rng = np.random.default_rng(seed)
    z = rng.normal(-2.0, 1.5, n)
    y = (rng.random(n) < 1 / (1 + np.exp(-z))).astype(np.int8)
    return (1 / (1 + np.exp(-(1.5 * z + shift)))).astype(np.float32), y


def _run(raw, labels, cal=STORED):
    stored = Calibrator(**cal).apply(raw) if cal else raw
    metrics = {"train_on": "sim", "history": [{"epoch": 0}], **({"calibration": cal} if cal else {})}
    return {"scores_arrays": {"probs": stored, "labels": labels}, "metrics": metrics}


def _res(run, threshold):
    """A map stack with one pixel per marker (score = its stored score), truth = its label."""
    s = run["scores_arrays"]
    stack = SimpleNamespace(score=s["probs"].reshape(1, 64, -1), visited=np.ones((1, 64, s["probs"].size // 64), bool),
                            truth=s["labels"].astype(bool).reshape(1, 64, -1))
    return SimpleNamespace(op=SimpleNamespace(threshold=threshold), stack=stack)


def _rows(x_run, x_res, y_run, y_res, partner="A-to-C"):
    return {r["calibration"]: r for r in seed_rows("A-to-B", x_run, x_res, partner, y_run, y_res,
                                                   ["stored", "cross_real", "cross_real_shift", "in_sample"])}


def test_own_labels_and_own_map_choose_nothing():
    (xr, xy), (yr, yy) = _set(0, 2.0), _set(1, 0.5)
    x, y = _run(xr, xy), _run(yr, yy)
    base = _rows(x, _res(x, 0.6), y, _res(y, 0.7))
    # X's labels flipped and its own map threshold moved: cross_real's scores and map threshold stay
    x_flip = _run(xr, 1 - xy)
    moved = _rows(x_flip, _res(x_flip, 0.2), y, _res(y, 0.7))
    for name in ("cross_real", "cross_real_shift"):
        np.testing.assert_array_equal(moved[name]["probs"], base[name]["probs"])
        assert moved[name]["map_pred_px"] == base[name]["map_pred_px"]
    assert moved["stored"]["map_pred_px"] != base["stored"]["map_pred_px"]  # the quirk-18 row uses its own map
    # the partner's labels and map are what cross_real is fitted on
    y_flip = _run(yr, 1 - yy)
    other = _rows(x, _res(x, 0.6), y_flip, _res(y_flip, 0.3))
    assert not np.array_equal(other["cross_real"]["probs"], base["cross_real"]["probs"])
    assert not np.array_equal(other["cross_real_shift"]["probs"], base["cross_real_shift"]["probs"])
    assert other["cross_real"]["map_pred_px"] != base["cross_real"]["map_pred_px"]
    assert base["cross_real"]["fitted_on"] == "meat (A-to-C scores)"
    assert base["cross_real"]["map_threshold_from"] == "meat map (SPEC §12 rule)"


def test_cross_fit_is_platt_on_the_partners_raw_scores_whatever_was_stored():
    (xr, xy), (yr, yy) = _set(0, 2.0), _set(1, 0.5)
    want = fit_calibrator(yr, yy, "platt").apply(xr)
    for cal in (STORED, None):
        got = _rows(_run(xr, xy, cal), _res(_run(xr, xy, cal), 0.5), _run(yr, yy, cal), _res(_run(yr, yy, cal), 0.5))
        np.testing.assert_allclose(got["cross_real"]["probs"], want, atol=1e-3)  # optimiser tolerance
    np.testing.assert_allclose(to_raw(Calibrator(**STORED).apply(xr), Calibrator(**STORED)), xr, rtol=1e-4, atol=1e-6)


def test_calibrated_half_is_the_map_threshold_of_d_bar_05():
    """d_bar_05 is the map of the pixels whose cross-calibrated score is >= 0.5, drawn from the stored scores (maps
    take a max per pixel, so the monotone calibration commutes with them)."""
    (xr, xy), (yr, yy) = _set(0, 2.0), _set(1, -1.0)
    x, y = _run(xr, xy), _run(yr, yy)
    rows = _rows(x, _res(x, 0.5), y, _res(y, 0.5))
    calibrated = {"scores_arrays": {"probs": rows["cross_real"]["probs"], "labels": xy}}
    assert 20 < (rows["cross_real"]["probs"] >= 0.5).sum() < xy.size - 20
    assert rows["cross_real"]["d_bar_05_mm"] == map_at(_res(calibrated, 0.5), 0.5)["d_bar_mm"]
    assert rows["cross_real"]["d_bar_05_mm"] != rows["stored"]["d_bar_05_mm"]


def test_no_partner_keeps_the_training_domains_calibration():
    (xr, xy), _ = _set(0, 2.0), None
    x = _run(xr, xy)
    x["metrics"]["train_on"] = "meat"
    rows = _rows(x, _res(x, 0.6), None, None, partner=None)
    assert rows["cross_real"]["fitted_on"] == "meat_val"
    np.testing.assert_array_equal(rows["cross_real"]["probs"], x["scores_arrays"]["probs"])
    assert rows["cross_real"]["map_threshold_from"] == "0.5 of the stored scores"
    assert rows["in_sample"]["fitted_on"].endswith("(itself: bound)")


def test_same_model_check():
    a = {"history": [{"epoch": 0, "val/ap": 0.3}], "calibration": STORED}
    assert same_model(a, dict(a)) and not same_model(a, {**a, "history": [{"epoch": 0, "val/ap": 0.31}]})


def test_partners_and_calibrations_are_checked_before_any_work(tmp_path):
    import pytest
    from omegaconf import OmegaConf

    from palpation.apps.recipe_crossfit import run

    base = {"out_dir": str(tmp_path), "experiments": ["A-to-B", "A-to-C"], "calibrations": ["cross_real"],
            "partners": {"A-to-B": "A-to-C", "A-to-C": "A-to-B"}}
    for bad, match in (({"partners": {"A-to-B": "A-to-B", "A-to-C": "A-to-B"}}, "partners.A-to-B"),
                       ({"partners": {"A-to-B": "C-to-B", "A-to-C": "A-to-B"}}, "partners.A-to-B"),
                       ({"partners": {"A-to-B": "A-to-C"}}, "partners.A-to-C"),
                       ({"calibrations": ["platt_on_test"]}, "unknown calibration")):
        with pytest.raises(ValueError, match=match):
            run(OmegaConf.create({**base, **bad}))


def test_cross_real_shift_keeps_the_stored_slope():
    """Only the intercept moves: the calibrated logit minus the stored logit is one constant, the one a shift fit on
    the partner's stored scores gives."""
    from palpation.metrics.calibration import logit

    (xr, xy), (yr, yy) = _set(0, 2.0), _set(1, -1.0)
    x, y = _run(xr, xy), _run(yr, yy)
    got = _rows(x, _res(x, 0.5), y, _res(y, 0.5))["cross_real_shift"]
    diff = logit(got["probs"]) - logit(x["scores_arrays"]["probs"])
    b = fit_calibrator(y["scores_arrays"]["probs"], yy, "shift").shift
    ok = (np.minimum(x["scores_arrays"]["probs"], got["probs"]) > 1e-4) & (
        np.maximum(x["scores_arrays"]["probs"], got["probs"]) < 1 - 1e-4)  # off the float32 ends
    assert ok.mean() > 0.5
    np.testing.assert_allclose(diff[ok], b, atol=1e-3)
    assert got["fitted_on"] == "meat (A-to-C scores; slope sim_val)"
