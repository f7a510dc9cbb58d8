"""The judge's device-time estimate (palpation.judge.budget): the counting and the bench fit."""

import pytest

from palpation.judge.budget import budget, slide_loop_envs, twin_seconds


def test_slide_loop_envs_worst_case_keeps_the_largest_rounds():
    # round 0 fit (3 trials) + held-out (2), then 3 rounds dropping the effect with the fewest candidates
    envs = slide_loop_envs({"a": 5, "b": 2, "c": 3}, n_fit=3, n_held=2, max_rounds=3)
    assert envs == [3, 2, 10 * 3, 2, 8 * 3, 2, 5 * 3, 2]
    assert slide_loop_envs({"a": 1}, 2, 2, max_rounds=4) == [2, 2, 2, 2]  # stops when no effect is left
    assert slide_loop_envs({"a": 1}, 2, 2, max_rounds=0) == [2, 2]
    # tpe: each round's asks come in `batches` sequential batches (2 asks per remaining effect each)
    assert slide_loop_envs({"a": 2, "b": 2}, 3, 2, max_rounds=2, batches=3) == [3, 2, 12, 12, 12, 2, 6, 6, 6, 2]
    # the inner gate: per round `batches` more batches of its own envs (tries x folds x asks x fitted trials)
    assert slide_loop_envs({"a": 2}, 3, 2, max_rounds=1, batches=2, gate_envs=18) == [3, 2, 6, 6, 18, 18, 2]


def test_twin_seconds_fits_frames_times_a_plus_b_envs():
    rows = [{"resolution": "reference", "device": "cuda:H100", "n_envs": n, "frames": 100, "setup_s": 1.0,
             "wall_s_measured": 1.0 + 100 * (0.002 + 0.0003 * n)} for n in (1, 8, 64)]
    rows.append({**rows[0], "device": "cpu", "wall_s_measured": 99.0})  # CPU rows are not priced
    a, b = twin_seconds(rows, "reference")
    assert a == pytest.approx(0.002) and b == pytest.approx(0.0003)
    with pytest.raises(ValueError, match="bench_twin.json"):
        twin_seconds(rows, "coarse")


def test_only_a_cuda_profile_with_the_judge_on_is_priced():
    with pytest.raises(ValueError, match=r"conf/workflow/quick\.yaml: judge_budget prices"):
        budget("quick", "unused")
