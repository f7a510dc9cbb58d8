"""The downstream judge (issue 12): cross-fitted Silicone scores, the choice by held-out slide MAE, the
slide-loop fold twin as a twin option, the table task end to end on toy runs."""

import numpy as np
import pandas as pd
import pytest
import yaml
from omegaconf import OmegaConf
from sklearn.metrics import average_precision_score

from palpation.io import save_json, save_text
from palpation.measured_sequences import save_sequence_set
from palpation.metrics.scores import Scores, save_scores
from palpation.report.runs import run_dir
from palpation.report.twin_selection import COLUMNS, Candidate, Member, crossfit, selection_table
from palpation.slides.twins import heldout_trials, twin_overrides, write_fold_twin

TRIALS = [1, 2, 3, 4]


def scores(rng, good: set[int]) -> Scores:
    """Toy Silicone scores, one clip per trial: trials in `good` separate the labels, others are noise."""
    seq = np.array([t - 1 for t in TRIALS])
    labels = (rng.random(127 * len(seq)) < 0.2).astype(np.int8)
    trial = np.repeat(seq + 1, 127)
    noise = rng.random(labels.size)
    probs = np.where(np.isin(trial, list(good)), 0.6 * labels + 0.4 * noise, noise).astype(np.float32)
    return Scores(probs, labels, seq, np.zeros(len(seq), np.int64))


def test_crossfit_scores_each_trial_by_the_twin_that_never_saw_it():
    rng = np.random.default_rng(0)
    # the odd twin's models are good on its own (fitted) trials only: a leak would inflate the pooled AP
    odd = Member([1, 3], {0: scores(rng, {1, 3})}, {0: scores(rng, set())})
    even = Member([2, 4], {0: scores(rng, {2, 4})}, {0: scores(rng, set())})
    p, y = crossfit([odd, even], 0)
    assert p.size == 4 * 127
    assert average_precision_score(y, p) < 0.5  # only the noisy held-out scores are pooled
    with pytest.raises(ValueError, match="held out of two"):
        crossfit([odd, Member([2], even.silicone, even.meat)], 0)
    with pytest.raises(ValueError, match=r"trials \[1, 3\] are scored by no twin"):
        crossfit([odd, Member(TRIALS, even.silicone, even.meat)], 0)


def test_table_chooses_the_lowest_heldout_slide_mae_only():
    rng = np.random.default_rng(1)
    whole = Member([], {0: scores(rng, set(TRIALS))}, {0: scores(rng, set(TRIALS))})
    folds = [Member([1, 3], {0: scores(rng, set())}, {0: scores(rng, set())}),
             Member([2, 4], {0: scores(rng, set())}, {0: scores(rng, set())})]
    cands = [Candidate("calibrated", "photos", [whole], 3.0, 1.1, 1.2),
             Candidate("slide_loop", "slides", folds, 2.0, 1.0, 1.2)]
    df = selection_table(cands)
    assert list(df.columns) == list(COLUMNS) and df["chosen"].sum() == 1
    # the better detector (calibrated) is not chosen: the choice reads the physics criterion only
    assert df.loc[df["chosen"], "twin"].item() == "slide_loop"
    assert df.loc[0, "silicone_ap_crossfit"] > df.loc[1, "silicone_ap_crossfit"]
    assert 0 <= df.loc[0, "silicone_pos_share_05"] <= 1 and df.loc[0, "seeds"] == 1
    with pytest.raises(ValueError, match="no candidate has a finite"):
        selection_table([Candidate("a", "x", [whole], float("nan"), 1.0, 1.0)])


def test_tie_rule_keeps_the_simplest_twin_unless_a_complex_one_is_significantly_better():
    """Pre-registered (docs/loop.md "Choice"): simplest first, one-sided Wilcoxon signed-rank per trial, alpha 0.05."""
    rng = np.random.default_rng(3)
    whole = Member([], {0: scores(rng, set())}, {0: scores(rng, set())})
    # the 26 Nov paper run's held-out per-trial MAE (docs/results/paper/judge/slides): photo_loop's mean was lower by
    # 1e-4 px and the earlier rule (lowest mean) chose it; the tie rule keeps calibrated
    cal = [3.5805, 1.3109, 1.3395, 1.3053, 1.5289, 1.5805, 2.8424, 1.7956, 1.4164, 1.5782]
    photo = [3.5788, 1.3110, 1.3404, 1.3052, 1.5289, 1.5793, 2.8430, 1.7969, 1.4168, 1.5771]

    def cand(name, mae):
        return Candidate(name, "x", [whole], float(np.mean(mae)), 1.0, 1.0, dict(enumerate(mae, 1)))

    df = selection_table([cand("calibrated", cal), cand("photo_loop", photo)])
    assert df["heldout_slide_mae_px"].iloc[1] < df["heldout_slide_mae_px"].iloc[0]
    assert df.loc[df["chosen"], "twin"].item() == "calibrated" and df.loc[1, "p_vs_simpler"] > 0.3
    better = [m - 0.2 + 0.01 * i for i, m in enumerate(cal)]  # lower on every trial
    df = selection_table([cand("calibrated", cal), cand("photo_loop", photo), cand("slide_loop", better)])
    assert df.loc[df["chosen"], "twin"].item() == "slide_loop" and df.loc[2, "p_vs_simpler"] < 0.01
    assert "significantly better than calibrated" in df.loc[2, "why"] and "replaced by slide_loop" in df.loc[0, "why"]
    with pytest.raises(ValueError, match="pairs trials"):
        selection_table([cand("calibrated", cal), cand("slide_loop", better[:5])])


def test_fold_twin_option(tmp_path):
    loop = {"folds": {"odd": [1, 3], "even": [2, 4]}, "size": {"frames": [5, 9]},
            "params": {"odd": [{"k_f": 1e7}, {"k_f": 1e8, "mount_dz_mm": 0.5, "mu": 0.3}], "even": [{"k_f": 1e7}]}}
    path = tmp_path / "twin_fit" / "fitted.yaml"
    write_fold_twin(loop, "odd", path, "toy")
    over = yaml.safe_load(path.read_text())
    assert over["contact"] == {"phantom_contact": True, "phantom_model": "foundation", "k_f": 1e8, "mu": 0.3}
    assert over["mount"]["dz"] == pytest.approx(5e-4)  # mm -> m (registry scale)
    assert path.read_text().startswith("# @package twin")
    assert heldout_trials(loop, "odd") == ([2, 4], [1, 3]) and heldout_trials(loop, None) == ([1, 2, 3, 4], [])
    with pytest.raises(ValueError, match="unknown parameter 'young'"):
        twin_overrides({"young": 1.0})


def test_table_task_end_to_end(tmp_path):
    from palpation.apps.twin_judge import table
    from tests.slides.test_replay import toy_set

    rng = np.random.default_rng(2)
    sset = toy_set(4, 3)
    save_sequence_set(tmp_path / "seq", sset)
    cfg = {"profile": "toy", "sequences": str(tmp_path / "seq"), "experiments": {"silicone": "A-to-B", "meat": "A-to-C"},
           "seeds": [0], "clip_len": 5, "figure_trial": None, "trained_with": "robust",
           "candidates": {"calibrated": {"fitted_on": "photos"},
                          "slide_loop": {"fitted_on": "slides", "folds": ["odd", "even"]}},
           "runs": {}, "slides": {}, "out": {k: str(tmp_path / "out" / v) for k, v in
                                             {"csv": "t.csv", "md": "t.md", "figure": "fig",
                                                                "bounds": "b.csv"}.items()}}
    for name, fold, scored, fitted, mae in (("calibrated", None, TRIALS, [], 3.0), ("slide_loop_odd", "odd", [2, 4], [1, 3], 2.0),
                                            ("slide_loop_even", "even", [1, 3], [2, 4], 2.5)):
        root = tmp_path / "runs" / name
        for exp in ("A-to-B", "A-to-C"):
            save_scores(run_dir(root, exp, 5, 0) / "scores.npz", scores(rng, set()))
        cfg["runs"][name] = str(root)
        cfg["slides"][name] = str(tmp_path / "slides" / f"{name}.json")
        save_json(cfg["slides"][name], {"trials": scored, "fitted_trials": fitted, "fold": fold, "frames": [0, 3],
                                        "mae_px": [mae] * len(scored), "vessel_ratio_sim": 1.0, "vessel_ratio_real": 1.1})
        np.savez(tmp_path / "slides" / f"{name}.npz", markers=sset.markers[[t - 1 for t in scored]], trials=scored)
    out = table(OmegaConf.create(cfg))
    # lower on all 4 trials, but 4 paired trials cannot reach the tie rule's 5 % (exact signed-rank p = 1/16):
    # the simpler twin stays
    assert out["chosen"] == "calibrated"
    md = (tmp_path / "out" / "t.md").read_text()
    assert "Models: recipe robust, every candidate alike." in md and "alpha 0.05" in md
    df = pd.read_csv(tmp_path / "out" / "t.csv")
    assert list(df.columns) == list(COLUMNS) and df["chosen"].sum() == 1
    assert df.loc[df["twin"] == "slide_loop", "heldout_slide_mae_px"].item() == pytest.approx(2.25)
    assert df.loc[1, "p_vs_simpler"] == pytest.approx(1 / 16) and df.loc[0, "why"].startswith("chosen: simplest")
    assert (tmp_path / "out" / "fig.png").exists() and (tmp_path / "out" / "fig.pdf").exists()
    bounds = pd.read_csv(tmp_path / "out" / "b.csv")  # on the replays' trials and frames (slides.diagnosis)
    assert list(bounds["predictor"])[0] == "no_motion" and bounds["change_vs_no_motion"].iloc[0] == 0
    # rule twin_choice (the main Sim set's twin) decides from the same replays by the same function: the same twin,
    # and the table refuses a choice.json that names another (stale replays on one side)
    from palpation.apps.twin_judge import choice

    fits = {n: str(tmp_path / n / "twin_fit" / "fitted.yaml") for n in cfg["slides"]}
    for path in fits.values():
        save_text(path, "# @package twin\nmaterial:\n  E: 1.0e6\n")
    made = choice(OmegaConf.create({**cfg, "fits": fits, "dataset_twin": "auto", "out": {
        "choice": str(tmp_path / "out" / "choice.json"), "choice_fit": str(tmp_path / "out" / "fit" / "fitted.yaml")}}))
    assert made["chosen"] == out["chosen"] == df.loc[df["chosen"], "twin"].item()
    assert table(OmegaConf.create({**cfg, "choice": str(tmp_path / "out" / "choice.json")}))["chosen"] == made["chosen"]
    assert "The main Sim set's twin: calibrated (the evidence's choice" in (tmp_path / "out" / "t.md").read_text()
    save_json(tmp_path / "out" / "stale.json", {**made, "chosen": "slide_loop"})
    with pytest.raises(ValueError, match="stale.json chose slide_loop but the table chooses calibrated"):
        table(OmegaConf.create({**cfg, "choice": str(tmp_path / "out" / "stale.json")}))


def test_the_page_reads_the_slide_loop_aim_against_the_drift_bounds():
    from palpation.report.page_judge import reachable

    df = pd.DataFrame({"twin": ["calibrated", "slide_loop"], "heldout_slide_mae_px": [2.0, 2.01]})
    bounds = pd.DataFrame({"predictor": ["no_motion", "other_fold_drift", "own_translation", "own_affine"],
                           "uses_heldout_truth": [False, False, True, True], "heldout_mae_px": [2.0, 2.02, 1.5, 1.2],
                           "change_vs_no_motion": [0.0, 0.01, -0.25, -0.4]})
    text, = reachable(df, bounds)
    assert "held-out MAE <= 1.400 px (30 % below calibrated's 2.000)" in text
    assert "other fold drift 2.020 px (+1.0 %)" in text and "own affine 1.200 px (-40.0 %)" in text
    assert "Even own translation misses it" in text
    bounds.loc[2, "heldout_mae_px"] = 1.3  # a bound that reaches the aim is not called a miss
    assert "misses it" not in reachable(df, bounds)[0]


def test_results_page_section_checks_the_aims():
    from palpation.report.page_judge import aim_checks, twin_selection_section

    df = pd.DataFrame([
        {"twin": "calibrated", "fitted_on": "photos", "heldout_slide_mae_px": 4.0, "vessel_ratio_sim": 1.1,
         "vessel_ratio_real": 1.2, "silicone_ap_crossfit": 0.32, "silicone_auroc_crossfit": 0.7, "meat_ap": 0.23,
         "meat_auroc": 0.6, "silicone_pos_share_05": 0.9, "seeds": 2, "chosen": False},
        {"twin": "slide_loop", "fitted_on": "slides", "heldout_slide_mae_px": 3.0, "vessel_ratio_sim": 1.0,
         "vessel_ratio_real": 1.2, "silicone_ap_crossfit": 0.40, "silicone_auroc_crossfit": 0.8, "meat_ap": 0.20,
         "meat_auroc": 0.6, "silicone_pos_share_05": 0.3, "seeds": 2, "chosen": True}])
    checks = {c[1]: c for c in aim_checks(df)}
    assert checks["silicone_ap_crossfit"][-1] == 0 and checks["meat_ap"][-1] == pytest.approx(0.06)
    assert checks["heldout MAE drop vs calibrated"][2] == pytest.approx(0.25)  # 25 % < the 30 % aim
    sec = twin_selection_section(df)
    assert "**yes**" in sec.body and any("missed by 0.06" in b for b in sec.bullets)
    rounds = pd.DataFrame({"fold": ["odd", "odd", "even"], "round": [0, 1, 0], "effect_added": ["none", "stiffness", "none"],
                           "mae_fit_px": [4.0, 2.0, 4.5], "mae_heldout_px": [4.0, 3.0, 5.0],
                           "vessel_ratio_sim": [1.1, 1.2, 1.0], "vessel_ratio_real": [1.3, 1.3, 0.8]})
    sec = twin_selection_section(df, rounds)
    assert "| odd | 1 | stiffness | 2.000 | 3.000 | 1.20 / 1.30 |" in sec.body
    assert "slide loop, fold odd: held-out motion MAE 4.000 -> 3.000 px (-25 %); added: stiffness." in sec.bullets
    assert "slide loop, fold even: held-out motion MAE 5.000 -> 5.000 px (+0 %); added: nothing." in sec.bullets
    rounds["at_bounds"] = [np.nan, "E=2e+06 at its upper bound [100000, 2e+06] Pa", np.nan]  # as read from the csv
    bullets = twin_selection_section(df, rounds).bullets
    assert any(b.startswith("slide loop, fold odd") and "Symptom: E=2e+06 at its upper bound" in b for b in bullets)
    assert "slide loop, fold even: held-out motion MAE 5.000 -> 5.000 px (+0 %); added: nothing." in bullets
    rounds["mae_inner_cv_px"], rounds["gate_p"] = [np.nan, 2.5, np.nan], [np.nan, 0.01, np.nan]  # the inner gate's
    assert "| odd | 1 | stiffness | 2.000 | 3.000 | 1.20 / 1.30 | 2.500 | 0.010 |" in twin_selection_section(df, rounds).body


def test_the_rule_s_table_overrides_compose():
    """rule twin_selection passes trained_with=<judge.recipe>: a plain key, not the `recipe` config group."""
    from hydra import compose, initialize_config_dir

    from palpation.paths import REPO_ROOT

    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose("twin_judge", overrides=["task=table", "trained_with=robust", "seeds=[0,1]"])
    assert cfg.trained_with == "robust" and "recipe" not in cfg


def test_a_significant_but_immaterial_gain_keeps_the_simplest_twin():
    """The tie rule's minimum effect: lower on every one of 10 trials (p 0.001) by 0.001-0.01 px is below the slide
    loop's keep threshold (0.05 px), so calibrated stays; the same gain at 0.06 px per trial replaces it."""
    rng = np.random.default_rng(4)
    whole = Member([], {0: scores(rng, set())}, {0: scores(rng, set())})
    cal = [3.5805, 1.3109, 1.3395, 1.3053, 1.5289, 1.5805, 2.8424, 1.7956, 1.4164, 1.5782]

    def table(gains):
        other = [m - g for m, g in zip(cal, gains)]
        return selection_table([Candidate("calibrated", "x", [whole], float(np.mean(cal)), 1.0, 1.0,
                                          dict(enumerate(cal, 1))),
                                Candidate("slide_loop", "x", [whole], float(np.mean(other)), 1.0, 1.0,
                                          dict(enumerate(other, 1)))])

    df = table([0.001 * (i + 1) for i in range(10)])
    assert df.loc[df["chosen"], "twin"].item() == "calibrated" and df.loc[1, "p_vs_simpler"] < 0.01
    assert "not materially better than calibrated" in df.loc[1, "why"] and "0.0055 px < 0.05 px" in df.loc[1, "why"]
    df = table([0.06 + 0.001 * i for i in range(10)])
    assert df.loc[df["chosen"], "twin"].item() == "slide_loop" and "mean gain 0.0645 px >= 0.05" in df.loc[1, "why"]
