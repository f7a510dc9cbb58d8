"""The recipe ablation table, the uncertainty table and the issue-15 figures on toy inputs."""

import numpy as np
import pytest

from palpation.figures.recipe import reliability_figure, uncertainty_figure
from palpation.io import save_figure
from palpation.mapping.uncertainty import EnsembleMap
from palpation.report.tables import (RECIPE_ABLATION_COLUMNS, UNCERTAINTY_COLUMNS, recipe_ablation,
                                     recipe_ablation_markdown, uncertainty_table)


def _row(recipe, switch, ap):
    return {"config": "A-to-B", "recipe": recipe, "switch_off": switch, "seeds": 2, "auroc_mean": 0.7,
            "auroc_std": 0.01, "ap_mean": ap, "ap_std": 0.02, "pos_share_05": 0.25, "ece": 0.04, "d_bar_mm": 2.5,
            "extra": 1}


def test_tables_have_the_issue_columns_in_order():
    df = recipe_ablation([_row("reference", "none", 0.2), _row("robust", "none", 0.3), _row("robust", "jitter", 0.28)])
    assert tuple(df.columns) == RECIPE_ABLATION_COLUMNS == (
        "config", "recipe", "switch_off", "seeds", "auroc_mean", "auroc_std", "ap_mean", "ap_std", "pos_share_05",
        "ece", "d_bar_mm")
    md = recipe_ablation_markdown(df, "quick", ["a note"])
    assert "| A-to-B (Sim→Silicone) | robust | jitter | 2 |" in md and "25.0 %" in md and "* a note" in md
    unc = uncertainty_table([{"config": "A-to-B/robust", "coverage": c, "precision": 0.5, "recall": 0.4, "n_pred": 3}
                             for c in (1.0, 0.8, 0.6, 0.4)])
    assert tuple(unc.columns) == UNCERTAINTY_COLUMNS == ("config", "coverage", "precision", "recall")
    assert unc["coverage"].tolist() == [1.0, 0.8, 0.6, 0.4]


@pytest.fixture
def toy_map():
    rng = np.random.default_rng(0)
    mean = rng.random((2, 6, 8)).astype(np.float32)
    visited = mean > 0.1
    return EnsembleMap(np.where(visited, mean, -1), rng.random((2, 6, 8)).astype(np.float32) * 0.2, visited,
                       mean > 0.8, 3, 0.5)


def test_figures_write_png_and_pdf(tmp_path, toy_map):
    rng = np.random.default_rng(1)
    p = rng.random(500)
    y = rng.random(500) < p
    fig = reliability_figure({"Sim→Silicone": {"reference": (p ** 0.3, y), "robust": (p, y)}}, "toy")
    assert [f.name for f in save_figure(fig, tmp_path / "reliability")] == ["reliability.png", "reliability.pdf"]
    curves = {"A-to-B/robust": toy_map.coverage_curve(1.0)}
    fig = uncertainty_figure({"A-to-B/robust": toy_map}, curves, "toy")
    assert all(f.stat().st_size > 0 for f in save_figure(fig, tmp_path / "uncertainty_maps"))


def test_recipe_report_run_in_mlflow(tmp_path, results_tmp):
    """The report's MLflow run: one name scheme, table metrics, tables and both figures as artefacts."""
    import mlflow

    from palpation import tracking
    from palpation.apps.recipe_report import _track

    for name in ("recipe_ablation.csv", "recipe_ablation.md", "uncertainty.csv", "recipe_report.json",
                 "reliability.png", "reliability.pdf", "uncertainty_maps.png", "uncertainty_maps.pdf"):
        (tmp_path / name).write_text("x")
    c = {"profile": "quick", "experiments": ["A-to-B"], "recipes": ["robust"], "switches": [], "seeds": [0],
         "clip_len": 5, "threshold": 0.5}
    row = {"config": "A-to-B", "recipe": "robust", "switch_off": "none", "auroc_mean": 0.6, "ap_mean": 0.2,
           "ap_std": 0.01, "pos_share_05": 0.1, "ece": 0.05, "d_bar_mm": float("nan")}
    _track(c, [row], tmp_path)
    [run] = mlflow.MlflowClient(tracking.tracking_uri()).search_runs(
        [mlflow.get_experiment_by_name("recipe_report").experiment_id])
    assert run.data.tags["mlflow.runName"] == "recipe_report/quick"
    assert run.data.metrics["A-to-B/robust/none/ap_mean"] == 0.2
    assert "A-to-B/robust/none/d_bar_mm" not in run.data.metrics  # NaN is not logged
    stored = {p.name for p in (results_tmp / "mlartifacts" / "recipe_report").rglob("*.*")}
    assert {"recipe_ablation.csv", "reliability.png", "uncertainty_maps.pdf"} <= stored


def test_switch_rows_only_for_the_listed_configurations():
    from palpation.apps.recipe_report import row_groups

    c = {"experiments": ["A-to-B", "C-to-B"], "recipes": ["reference", "robust"], "switches": ["jitter", "scale"]}
    full = [("reference", "none"), ("robust", "none")]
    assert row_groups(c, "C-to-B") == full + [("robust", "jitter"), ("robust", "scale")]  # missing key: all
    c["switch_experiments"] = ["A-to-B"]  # the paper profile's cut
    assert row_groups(c, "C-to-B") == full
    assert row_groups(c, "A-to-B")[2:] == [("robust", "jitter"), ("robust", "scale")]


def test_partial_report_leaves_out_rows_with_missing_runs_and_says_so(tmp_path):
    """partial=true: a row with a missing seed is reported missing (never averaged over fewer); off, it is an error."""
    import json

    from palpation.apps.recipe_report import load_group, partial_note
    from palpation.report.page_recipe import recipe_ablation_section
    from palpation.report.runs import recipe_root, run_dir

    c = {"runs_root": str(tmp_path), "seeds": [0, 1], "clip_len": 5}
    d = run_dir(recipe_root(tmp_path, "robust", "none"), "A-to-B", 5, 0)
    d.mkdir(parents=True)
    (d / "metrics.json").write_text(json.dumps({"test": {"auroc": 0.7, "ap": 0.3}}))
    with pytest.raises(FileNotFoundError, match="seed1.*partial=true"):
        load_group(c, "A-to-B", "robust", "none")
    runs, missing = load_group({**c, "partial": True}, "A-to-B", "robust", "none")
    assert [r["seed"] for r in runs] == [0] and missing == [1]
    assert load_group({**c, "partial": True}, "A-to-B", "robust", "jitter") == ([], [0, 1])
    left = [{"config": "A-to-B", "recipe": "robust", "switch_off": "jitter", "missing_seeds": [0, 1]}]
    assert "A-to-B robust minus jitter (seeds [0, 1])" in partial_note(left, "out of device time")
    df = recipe_ablation([_row("robust", "none", 0.3)])
    body = recipe_ablation_section(df, {"left_out": left, "partial_reason": "out of device time"}).body
    assert "**Partial table**: 1 row(s)" in body and "switch off `jitter`: runs of seeds 0, 1 missing" in body
    assert "out of device time" in body
    assert "Partial" not in recipe_ablation_section(df, {"left_out": []}).body


def test_trajectory_check_compares_the_common_epochs_seed_by_seed():
    """A switch that only changes where training stops follows the full recipe's epochs: 0 for a copy over the epochs
    both ran, and the largest difference where a Sim set or code changed."""
    from palpation.apps.recipe_report import trajectory_check

    def run(seed, losses, ious, aps=None):
        hist = [{"epoch": e, "train/loss": l, "val/fg_iou": i, **({"val/ap": aps[e]} if aps else {})}
                for e, (l, i) in enumerate(zip(losses, ious))]
        return {"seed": seed, "metrics": {"history": hist}}

    full = [run(0, [0.005, 0.004], [0.22, 0.20], [0.35, 0.33]), run(1, [0.006, 0.005], [0.21, 0.19], [0.34, 0.32])]
    same = [run(0, [0.005, 0.004, 0.0039], [0.22, 0.20, 0.21], [0.35, 0.33, 0.34]), run(1, [0.006], [0.21], [0.34])]
    assert trajectory_check(full, same) == {"epochs_compared": 3, "max_rel_train_loss": 0.0,
                                            "max_abs_val_fg_iou": 0.0, "max_abs_val_ap": 0.0}
    moved = [run(1, [0.006, 0.0055], [0.21, 0.17])]  # select_ap off: no val/ap in its history
    got = trajectory_check(full, moved)
    assert got["epochs_compared"] == 2 and got["max_rel_train_loss"] == pytest.approx(0.1)
    assert got["max_abs_val_fg_iou"] == pytest.approx(0.02) and got["max_abs_val_ap"] == 0.0


def test_kept_validation_reads_the_kept_epochs_val_ap():
    from palpation.apps.recipe_report import kept_validation

    hist = [{"epoch": 0, "val/ap": 0.35}, {"epoch": 1, "val/ap": 0.33}]
    assert kept_validation({"history": hist, "best_epoch": 0}) == (0.35, 0)
    v, e = kept_validation({"history": [{"epoch": 0, "val/fg_iou": 0.2}], "best_epoch": 0})  # selected by FG IoU
    assert v != v and e == 0
    v, _ = kept_validation({"best_epoch": 3})
    assert v != v


def test_reference_rows_apart_from_the_seed_sweep_are_flagged():
    """The ablation's reference rows and the seed sweep train the same recipe: AP apart beyond seed noise means
    another Sim set, and the page says so; within noise it says nothing."""
    import pandas as pd

    from palpation.report.page_recipe import sweep_mismatch

    df = pd.DataFrame([dict(config="A-to-B", recipe="reference", switch_off="none", seeds=5, ap_mean=0.280,
                            ap_std=0.006), dict(config="A-to-B", recipe="robust", switch_off="none", seeds=5,
                                                 ap_mean=0.200, ap_std=0.006)])
    sweep = pd.DataFrame({"config": ["A-to-B"] * 5, "ap": [0.315, 0.320, 0.323, 0.326, 0.331]})
    (line,) = sweep_mismatch(df, sweep)
    assert line.startswith("A-to-B (Sim→Silicone), reference: AP 0.2800 here vs 0.3230 in the seed sweep")
    assert sweep_mismatch(df, sweep.assign(ap=sweep["ap"] - 0.043)) == []  # the same Sim set: within noise
    assert sweep_mismatch(df, None) == []
