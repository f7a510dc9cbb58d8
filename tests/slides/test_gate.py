"""The slide loop's inner gate (issue 12): an effect is kept only if, fitted without a trial of the fitting fold,
it scores that trial better than the current twin (paired test over the fold's trials)."""

import numpy as np
import pytest

from palpation.slides.gate import GateSettings, inner_splits, paired_p, verdict
from palpation.slides.loop import SearchSettings, SlideLoopSettings, run_slide_loop
from palpation.slides.replay import motion

from tests.slides.test_replay import toy_set

# per trial, where the phantom's slope "wants" to be: it alternates, so a slope fitted on some trials of a fold
# lowers their error but not the error of a trial it did not see (an overfit, like the paper run's phantom_tilt)
SLOPE = {1: 0.02, 2: -0.02, 3: -0.02, 4: 0.02, 5: 0.02, 6: -0.02}


def fake_twin(truth):
    """Motion error per trial = |mu - 0.8| (a real effect: the same optimum on every trial) + 25 |tilt - SLOPE|."""
    calls = []

    def evaluate(part, cands):
        calls.append(len(cands))
        idx = [int(t["name"][1:]) for t in part.trials]
        out = []
        for c in cands:
            err = np.array([abs(c.get("mu", 0.0) - 0.8) + 25 * abs(c.get("tilt_y", 0.0) - SLOPE[t]) for t in idx])
            real = truth[[t - 1 for t in idx]]
            out.append(real + 5.0 + err[:, None, None, None] * motion(real))
        return np.stack(out), np.zeros((len(cands), part.n_trials), bool)
    return evaluate, calls


def settings(inner: bool, sampler="grid", **gate):
    return SlideLoopSettings(effects={"friction": {"mu": [0.3, 0.8]}, "phantom_tilt": {"tilt_y": [-0.02, 0.02]}},
                             base={}, max_rounds=2, min_improvement_px=0.01,
                             search=SearchSettings(sampler=sampler, batches=2, per_batch=3, seed=1),
                             gate=GateSettings(inner=inner, **gate)).validate()


def test_inner_gate_refuses_an_effect_that_only_fits_the_trials_it_saw():
    s = toy_set(6, 3)
    truth = s.markers.astype(np.float64)
    free = run_slide_loop(fake_twin(truth)[0], s, settings(False), [1, 2, 3, 4, 5, 6])
    gated = run_slide_loop(fake_twin(truth)[0], s, settings(True), [1, 2, 3, 4, 5, 6])
    for fold in ("odd", "even"):
        old = [r for r in free["rows"] if r["fold"] == fold]
        new = [r for r in gated["rows"] if r["fold"] == fold]
        # without the gate the slope is kept on the fitted trials' word and the other fold gets worse
        assert [r["effect_added"] for r in old] == ["none", "friction", "phantom_tilt"]
        assert old[2]["mae_fit_px"] < old[1]["mae_fit_px"] and old[2]["mae_heldout_px"] > old[1]["mae_heldout_px"]
        # with it the real effect passes (every left-out trial improves) and the slope is refused
        assert [r["effect_added"] for r in new] == ["none", "friction"]
        assert new[1]["gate_p"] < 0.05 and new[1]["mae_inner_cv_px"] < new[0]["mae_fit_px"]
        assert np.isnan(old[1]["gate_p"]) and np.isnan(new[0]["mae_inner_cv_px"])
        slope = [t for t in gated["gate"] if t["fold"] == fold and t["effect"] == "phantom_tilt"]
        assert slope and not any(t["passed"] for t in slope) and all(t["gain_px"] < 0 for t in slope)


def test_inner_gate_with_the_continuous_search_is_seeded_and_batched():
    s = toy_set(6, 3)
    truth = s.markers.astype(np.float64)
    evaluate, calls = fake_twin(truth)
    one = run_slide_loop(evaluate, s, settings(True, "tpe", tries=1), [1, 2, 3, 4, 5, 6])
    # per fold: base fit + held-out, round 1: 2 search batches (2 effects x 3 asks), 2 inner batches (1 effect x
    # 3 left-out trials x 3 asks), the kept twin's held-out replay; round 2 the same with one effect left
    assert calls[:7] == [1, 1, 6, 6, 9, 9, 1] and calls[7:9] == [3, 3]
    assert [r["effect_added"] for r in one["rows"] if r["fold"] == "odd"][:2] == ["none", "friction"]
    again = run_slide_loop(fake_twin(truth)[0], s, settings(True, "tpe", tries=1), [1, 2, 3, 4, 5, 6])
    assert again["params"] == one["params"] and again["gate"] == one["gate"]


def test_a_fold_of_one_trial_keeps_nothing():
    s = toy_set(2, 3)
    result = run_slide_loop(fake_twin(s.markers.astype(np.float64))[0], s, settings(True), [1, 2])
    assert [r["effect_added"] for r in result["rows"]] == ["none", "none"]
    assert all(not t["passed"] and np.isnan(t["mae_inner_cv_px"]) and t["p"] == 1.0 for t in result["gate"])


def test_paired_test_and_splits():
    assert [x.tolist() for x in inner_splits(5, None)] == [[0], [1], [2], [3], [4]]
    assert [x.tolist() for x in inner_splits(5, 2)] == [[0, 2, 4], [1, 3]]
    assert inner_splits(1, None) == []  # one trial: nothing to leave out, the gate refuses
    before = np.array([2.0, 1.5, 1.8, 2.2, 1.6])
    assert paired_p(before, before - 0.3 + 0.01 * np.arange(5), "t") < 0.01
    assert paired_p(before, before - 0.3, "wilcoxon") == pytest.approx(1 / 32)  # exact: all 5 trials better
    assert paired_p(before, before + 0.1, "t") > 0.5 and paired_p(before, before, "t") == 1.0
    noisy = before + np.array([-0.4, 0.3, -0.2, 0.25, -0.1])  # better on average by 0.03 px, within the noise
    v = verdict(before, noisy, GateSettings(inner=True), 0.01)
    assert not v["passed"] and v["p"] > 0.05
    assert not verdict(before[:1], before[:1] - 1, GateSettings(inner=True), 0.01)["passed"]
    with pytest.raises(ValueError, match="gate.test"):
        GateSettings(test="z").validate()
