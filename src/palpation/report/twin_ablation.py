"""Does the residual loop's twin make better training data? The same Sim draws simulated with the
calibration-only twin (the paper's pipeline) and with the loop's final twin, same models and seeds,
scored on the same real test set. One row per (dataset twin, configuration)."""

from __future__ import annotations

import pandas as pd

from palpation.report.paper import CONFIG_TITLES, SEED_SWEEP
from palpation.report.markdown import markdown, pm_seeds

COLUMNS = ("dataset_twin", "experiment", "n_seeds", "auroc_mean", "auroc_std", "ap_mean", "ap_std",
           "fg_iou_mean", "bg_iou_mean")
METRICS = ("auroc", "ap", "fg_iou", "bg_iou")


def twin_ablation(runs_by_twin: dict[str, list[dict]]) -> pd.DataFrame:
    """runs_by_twin: dataset twin name -> metric records of palpation.report.runs.load_runs. Mean and sample
    std (ddof 1, NaN for one seed) per (twin, configuration) in first-seen order; the CSV's %.6g hides the
    last-bit differences from numpy's sums."""
    frames = [pd.DataFrame(runs).assign(dataset_twin=twin) for twin, runs in runs_by_twin.items() if runs]
    if not frames:
        return pd.DataFrame(columns=list(COLUMNS))
    stats = {c: (c.rsplit("_", 1)[0], c.rsplit("_", 1)[1]) for c in COLUMNS if c.endswith(("_mean", "_std"))}
    out = (pd.concat(frames).groupby(["dataset_twin", "config"], sort=False)
           .agg(n_seeds=("auroc", "size"), **stats).reset_index().rename(columns={"config": "experiment"}))
    return out[list(COLUMNS)]


def twin_ablation_markdown(runs_by_twin: dict[str, list[dict]], profile: str) -> str:
    rows = []
    configs = dict.fromkeys(r["config"] for runs in runs_by_twin.values() for r in runs)
    for config in configs:
        for twin, runs in runs_by_twin.items():
            mine = [r for r in runs if r["config"] == config]
            if mine:
                rows.append([f"{config} ({CONFIG_TITLES.get(config, config)})", f"{twin} twin",
                             len(mine)] + [pm_seeds([r[m] for r in mine]) for m in METRICS])
        if config in SEED_SWEEP:
            rows.append([config, "paper (calibrated twin)", 5]
                        + [f"{SEED_SWEEP[config][m][0]:.4f} ± {SEED_SWEEP[config][m][1]:.4f}" for m in METRICS])
    return (f"# Dataset twin ablation ({profile} profile): mean ± sample std over seeds\n\n"
            "Same Sim draws, models and seeds; only the twin that simulated the training set differs.\n\n"
            + markdown(["Config", "Sim data from", "seeds", "AUROC", "AP", "FG IoU", "BG IoU"], rows))
