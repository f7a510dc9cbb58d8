"""The transfer table's selection rules on toy run records: the cross-real choice is made on the other real set,
never on the scored set's labels; cross-fitting chooses each fold on the other folds; the CSV's exact columns."""

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from palpation.io import save_json
from palpation.metrics.scores import Scores, load_scores, save_scores
from palpation.paths import REPO_ROOT
from palpation.report.runs import run_dir
from palpation.transfer.report import COLUMNS, read_methods, table
from palpation.transfer.selection import crossfit_by_trials

SEEDS = (0, 1, 2)
METHODS = {"m1": {"about": "a", "transductive": False, "overrides": []},
           "m2": {"about": "b", "transductive": False, "overrides": []},
           "m3": {"about": "c", "transductive": True, "overrides": ["recipe.align=coral"]}}
# how well each method ranks each set's markers (the toy scores' signal): m1 is best on Silicone and on the Sim val
# split, m2 on Meat; m3 (transductive) weak everywhere
SIGNAL = {"m1": {"silicone": 2.0, "meat": 0.5, "sim val": 0.6, "meat val": 0.7},
          "m2": {"silicone": 1.0, "meat": 2.0, "sim val": 0.4, "meat val": 0.5},
          "m3": {"silicone": 0.3, "meat": 0.3, "sim val": 0.1, "meat val": 0.1}}
TESTS = {"A-to-B": ("sim", "silicone"), "A-to-C": ("sim", "meat"), "C-to-B": ("meat", "silicone")}


def _scores(signal, seed, n_clips=24):
    rng = np.random.default_rng(seed)
    labels = (rng.random(n_clips * 127) < 0.1).astype(np.int8)
    probs = 1 / (1 + np.exp(-(signal * labels + rng.normal(0, 1, labels.size) - 2)))
    return Scores(probs.astype(np.float32), labels, np.repeat(np.arange(6), n_clips // 6), np.arange(n_clips) % 4)


def write_runs(root):
    for m in METHODS:
        for config, (train_on, test_on) in TESTS.items():
            for s in SEEDS:
                out = run_dir(root / m, config, 5, s)
                save_scores(out / "scores.npz", _scores(SIGNAL[m][test_on], 100 * s + len(config + test_on)))
                val = SIGNAL[m][f"{train_on} val"] + 0.01 * s
                metrics = {"config": config, "train_on": train_on, "test_on": test_on, "seed": s, "best_epoch": 0,
                           "history": [{"epoch": 0, "val/ap": val}]}
                if train_on == "sim":  # A-to-B and A-to-C: one training scored on both real sets
                    metrics["trained_together"] = {"seeds": list(SEEDS), "configs": ["A-to-B", "A-to-C"]}
                if METHODS[m]["transductive"]:
                    metrics["alignment"] = {"method": "coral", "stats_from": "test_set", "transductive": True}
                save_json(out / "metrics.json", metrics)


def _rows(rows, **where):
    return [r for r in rows if all(r[k] == v for k, v in where.items())]


def test_cross_real_choice_is_made_on_the_other_real_set(tmp_path):
    write_runs(tmp_path)
    rows = table(tmp_path, METHODS, list(TESTS), list(SEEDS), 5)
    chosen = {(r["config"], r["selection"], r["transductive"]): r["method"] for r in rows if r["chosen"]}
    # A-to-B: Meat (the other real set) prefers m2 though m1 scores best on Silicone; the Sim val split picks m1
    assert chosen[("A-to-B", "cross_real", False)] == "m2" and chosen[("A-to-B", "sim_val", False)] == "m1"
    ab = {r["method"]: r for r in _rows(rows, config="A-to-B", selection="cross_real")}
    assert ab["m1"]["ap_mean"] > ab["m2"]["ap_mean"] and ab["m2"]["chosen_on"] == ["meat method half (A-to-C)"]
    assert chosen[("A-to-C", "cross_real", False)] == "m1"  # Silicone prefers m1
    # C-to-B: chosen on its Meat val trials; no Sim val split, so no sim_val rows
    assert chosen[("C-to-B", "cross_real", False)] == "m1" and not _rows(rows, config="C-to-B", selection="sim_val")
    assert _rows(rows, config="C-to-B", method="m1")[0]["chosen_on"] == ["meat val"]
    # transductive methods are chosen apart: one chosen row per (config, selection, transductive)
    assert chosen[("A-to-B", "cross_real", True)] == "m3"
    assert len(chosen) == len({(r["config"], r["selection"], r["transductive"]) for r in rows})


def test_scored_set_labels_never_choose(tmp_path):
    """Garbage labels on A-to-B's scored set (Silicone) change its reported AP, not what any rule chose for it."""
    write_runs(tmp_path)
    before = table(tmp_path, METHODS, list(TESTS), list(SEEDS), 5)
    rng = np.random.default_rng(7)
    for m in METHODS:
        for s in SEEDS:
            path = run_dir(tmp_path / m, "A-to-B", 5, s) / "scores.npz"
            sc = load_scores(path)
            save_scores(path, Scores(sc.probs, rng.integers(0, 2, sc.labels.size).astype(np.int8), sc.sequence,
                                     sc.frame))
    after = table(tmp_path, METHODS, list(TESTS), list(SEEDS), 5)
    pick = lambda rows: [(r["method"], r["selection"], r["chosen"]) for r in _rows(rows, config="A-to-B")]  # noqa
    assert pick(before) == pick(after)
    assert [r["ap_mean"] for r in _rows(before, config="A-to-B")] != [r["ap_mean"] for r in _rows(after, config="A-to-B")]


def test_cross_real_scores_the_method_half_and_refuses_a_checkpoint_chosen_on_all_of_it(tmp_path):
    """A method that chose its checkpoint on Meat's selection half is scored on Meat's method half by its partner
    run (`A-to-B.on_meat`), like every other method; the selection half's labels move no score; a checkpoint
    chosen on all of Meat is refused."""
    write_runs(tmp_path)
    for s in SEEDS:  # m2 now chooses on Meat's selection half and scores Meat through its partner
        meta = {"selected_on": "meat half", "selected_trials": ["t0", "t2", "t4"]}
        ab = run_dir(tmp_path / "m2", "A-to-B", 5, s)
        m = json.loads((ab / "metrics.json").read_text())
        together = {"seeds": list(SEEDS), "configs": ["A-to-B", "A-to-B.on_meat"]}
        save_json(ab / "metrics.json", {**m, **meta, "trained_together": together})
        partner = run_dir(tmp_path / "m2", "A-to-B.on_meat", 5, s)
        save_scores(partner / "scores.npz", _scores(SIGNAL["m2"]["meat"], 100 * s + 11))
        save_json(partner / "metrics.json", {**m, **meta, "config": "A-to-B.on_meat", "test_on": "meat",
                                             "trained_together": together})
    rows = table(tmp_path, METHODS, ["A-to-B"], list(SEEDS), 5)
    got = {r["method"]: r for r in _rows(rows, selection="cross_real")}
    assert got["m2"]["chosen_on"] == ["meat method half (A-to-B.on_meat)"] and got["m2"]["chosen"]
    rng = np.random.default_rng(5)
    for m in METHODS:  # garbage labels on the selection half (even positions) of every Meat score
        for config in ("A-to-C", "A-to-B.on_meat"):
            for s in SEEDS:
                path = run_dir(tmp_path / m, config, 5, s) / "scores.npz"
                if path.exists():
                    sc = load_scores(path)
                    even = np.repeat(sc.sequence % 2 == 0, 127)
                    save_scores(path, Scores(sc.probs, np.where(even, rng.integers(0, 2, sc.labels.size),
                                                                sc.labels).astype(np.int8), sc.sequence, sc.frame))
    again = {r["method"]: r["selection_score"] for r in _rows(table(tmp_path, METHODS, ["A-to-B"], list(SEEDS), 5),
                                                                  selection="cross_real")}
    assert again == {m: r["selection_score"] for m, r in got.items()}
    for s in SEEDS:
        ab = run_dir(tmp_path / "m2", "A-to-B", 5, s) / "metrics.json"
        save_json(ab, {**json.loads(ab.read_text()), "selected_on": "meat all"})
    with pytest.raises(ValueError, match="chosen on every meat trial"):
        table(tmp_path, METHODS, ["A-to-B"], list(SEEDS), 5)


def test_undeclared_transductive_method_and_missing_runs_are_refused(tmp_path):
    write_runs(tmp_path)
    with pytest.raises(ValueError, match="declare it transductive"):
        table(tmp_path, {**METHODS, "m3": {**METHODS["m3"], "transductive": False}}, list(TESTS), list(SEEDS), 5)
    with pytest.raises(FileNotFoundError, match="seed3"):
        table(tmp_path, METHODS, list(TESTS), [0, 1, 2, 3], 5)


def test_crossfit_chooses_each_fold_on_the_other_folds_only():
    per_method = {m: [_scores(SIGNAL[m]["meat"], s) for s in SEEDS] for m in ("m1", "m2")}
    fit = crossfit_by_trials(per_method, 2)
    assert fit["folds"] == [[0, 2, 4], [1, 3, 5]] and fit["choices"] == ["m2", "m2"]
    rng = np.random.default_rng(3)
    for k, fold in enumerate(fit["folds"]):  # garbage labels in a fold leave that fold's own choice alone
        garbled = {m: [Scores(s.probs, np.where(np.repeat(np.isin(s.sequence, fold), 127),
                                                rng.integers(0, 2, s.labels.size), s.labels).astype(np.int8),
                              s.sequence, s.frame) for s in v] for m, v in per_method.items()}
        assert crossfit_by_trials(garbled, 2)["choices"][k] == fit["choices"][k]
    # and it does read the other folds: making m1 perfect there moves fold 0's choice
    perfect = {"m1": [Scores(np.where(np.repeat(np.isin(s.sequence, fit["folds"][1]), 127), s.labels, s.probs)
                             .astype(np.float32), s.labels, s.sequence, s.frame) for s in per_method["m1"]],
               "m2": per_method["m2"]}
    assert crossfit_by_trials(perfect, 2)["choices"][0] == "m1"


def write_methods(path):
    """METHODS as a methods file (conf/transfer/methods.yaml's format), every method without overrides."""
    path.write_text("methods:\n" + "".join(
        f"  {m}:\n    about: {v['about']}\n    transductive: {str(v['transductive']).lower()}\n    overrides: []\n"
        for m, v in METHODS.items()))
    return path


def test_script_writes_exactly_the_columns_and_the_shipped_methods_read(tmp_path):
    write_runs(tmp_path / "runs")
    methods = write_methods(tmp_path / "methods.yaml")
    out = tmp_path / "docs" / "transfer.csv"
    r = subprocess.run([sys.executable, str(REPO_ROOT / "workflow/scripts/transfer_table.py"), "--runs-root",
                        str(tmp_path / "runs"), "--methods", str(methods), "--seeds", "0", "1", "2", "--out", str(out),
                        "--crossfit", "C-to-B=2"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    with open(out) as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == COLUMNS and {r["selection"] for r in rows} == {"sim_val", "cross_real"}
    assert {r["seeds"] for r in rows} == {"3"} and out.with_suffix(".json").exists()
    crossfit = [r for r in rows if r["method"].startswith("crossfit(")]
    assert [r["transductive"] for r in crossfit] == ["false", "true"] and all(r["chosen"] == "true" for r in crossfit)
    assert set(read_methods(REPO_ROOT / "conf/transfer/methods.yaml")) >= {"reference", "robust"}
    methods.write_text("methods:\n  m1: {about: a, transductive: false, overrides: [], extra: 1}\n")
    r = subprocess.run([sys.executable, str(REPO_ROOT / "workflow/scripts/transfer_table.py"), "--runs-root",
                        str(tmp_path / "runs"), "--methods", str(methods), "--out", str(out)], capture_output=True,
                       text=True)
    assert r.returncode == 1 and "needs exactly the keys" in r.stderr


def test_left_out_methods_leave_no_row_and_are_recorded(tmp_path):
    write_runs(tmp_path / "runs")
    methods = write_methods(tmp_path / "methods.yaml")
    left = sorted(METHODS)[-1]
    out = tmp_path / "transfer.csv"
    script = [sys.executable, str(REPO_ROOT / "workflow/scripts/transfer_table.py"), "--runs-root",
              str(tmp_path / "runs"), "--methods", str(methods), "--seeds", "0", "1", "2", "--out", str(out)]
    r = subprocess.run(script + ["--leave-out", left], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    with open(out) as f:
        assert left not in {row["method"] for row in csv.DictReader(f)}
    assert json.loads(out.with_suffix(".json").read_text())["left_out"] == [left]
    r = subprocess.run(script + ["--leave-out", "no_such_method"], capture_output=True, text=True)
    assert r.returncode == 1 and "no_such_method" in r.stderr and r.stderr.count("\n") == 1
