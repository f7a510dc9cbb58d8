"""slides.diagnosis.drift_bounds: what a held-out slide MAE can reach without a twin (issue 12), on toy
slides whose answer is known."""

import numpy as np
import pytest

from palpation.measured_sequences import make_sequence_set
from palpation.slides.diagnosis import BOUNDS_COLUMNS, drift_bounds

F = 12
RNG = np.random.default_rng(3)
REST = RNG.uniform(0, 400, (127, 2))


def toy_set(drift) -> "object":
    """Four slides on two lanes (x = 0, 30 mm), trials 1 and 3 along -y, 2 and 4 along +y; every marker moves by
    drift(trial, y positions, direction) (F, 2) px in the image, whose axes are the world's."""
    pose, markers = [], []
    for t in range(4):
        lane, sign = 30.0 * (t // 2), -1.0 if t % 2 == 0 else 1.0
        y = sign * np.linspace(-30, 30, F)
        pose.append(np.stack([np.full(F, lane), y, np.full(F, 3.0)], -1))
        markers.append(REST[None] + drift(t, y, sign)[:, None, :])
    return make_sequence_set(np.array(markers), np.ones((4, F, 127), bool), REST, np.array(pose),
                             [np.array([[0.0, -40.0], [0.0, 40.0]])], [{"name": f"t{t + 1}"} for t in range(4)])


def rows(sset) -> dict:
    df = drift_bounds(sset, [1, 2, 3, 4])
    assert tuple(df.columns) == BOUNDS_COLUMNS
    return df.set_index("predictor")["heldout_mae_px"].to_dict()


def test_a_drift_shared_in_time_is_predicted_by_the_other_fold():
    # a transient along the motion after the slide starts: the same in every trial, turned with the direction
    along = lambda t, y, sign: np.stack([np.zeros(F), sign * 3.0 * np.exp(-np.arange(F) / 3.0)], -1)
    mae = rows(toy_set(along))
    assert mae["no_motion"] > 0.5
    assert mae["other_fold_drift"] == pytest.approx(0.0, abs=1e-4)
    assert mae["own_translation"] == pytest.approx(0.0, abs=1e-4)
    assert mae["own_affine"] == pytest.approx(0.0, abs=1e-4)
    assert mae["same_lane_drift"] > 0.3  # a transient in time is not a function of place


def test_a_drift_tied_to_place_is_predicted_by_the_same_lane_only():
    # a surface shape: the along-motion drift is a function of y on each lane (lanes differ), whatever the direction
    bump = lambda t, y, sign: np.stack([np.zeros(F), sign * (2.0 if t < 2 else -1.0) * np.sin(y / 12.0)], -1)
    mae = rows(toy_set(bump))
    assert mae["same_lane_drift"] == pytest.approx(0.0, abs=1e-4)
    assert mae["other_fold_drift"] > 0.3
    assert mae["own_translation"] == pytest.approx(0.0, abs=1e-4)


def test_a_trial_specific_drift_leaves_only_the_bounds():
    noise = {t: RNG.normal(0, 2.0, (F, 2)) for t in range(4)}
    mae = rows(toy_set(lambda t, y, sign: noise[t]))
    assert mae["other_fold_drift"] > 0.9 * mae["no_motion"]
    assert mae["own_translation"] == pytest.approx(0.0, abs=1e-4)
    df = drift_bounds(toy_set(lambda t, y, sign: noise[t]), [1, 2, 3, 4]).set_index("predictor")
    assert df.loc["no_motion", "change_vs_no_motion"] == 0.0
    assert df.loc["own_translation", "change_vs_no_motion"] == pytest.approx(-1.0, abs=1e-4)
    assert bool(df.loc["own_translation", "uses_heldout_truth"]) and not bool(df.loc["no_motion", "uses_heldout_truth"])
