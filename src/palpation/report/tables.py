"""The paper's tables as CSV frames and Markdown beside the paper's rows (SPEC §15): seed sweep, Table 3,
Table 4 upper half (per marker) and lower half (vessel maps). The results page compares the same frames
(report.page_training); cells are formatted by report.markdown."""

from __future__ import annotations

import pandas as pd

from palpation.metrics.aggregate import best_of_five
from palpation.report.markdown import markdown, num, pm, pm_seeds
from palpation.report.paper import (CONFIG_TITLES, MAPS_PHOTO_THRESHOLD, PAPER_DIGITS, SEED_SWEEP, TABLE3, TABLE4,
                                    TABLE4_MAPS)
from palpation.report.runs import SWEEP_COLUMNS

TABLE4_COLUMNS = ("config", "seed", "tp", "fp", "fn", "tn", "mcc", "f1", "precision", "recall",
                  "fg_iou", "bg_iou", "ap", "auroc")
ABLATION_COLUMNS = ("clip_len", "seed", "fg_iou", "ap")
MAPS_COLUMNS = ("config", "threshold", "threshold_rule", "tp", "fp", "fn", "tn", "mcc", "f1", "precision", "recall",
                "fg_iou", "bg_iou", "ap", "d_bar_mm")
COUNTS = ("tp", "fp", "fn", "tn")


def seed_sweep(runs: list[dict]) -> pd.DataFrame:
    return pd.DataFrame([{k: r[k] for k in SWEEP_COLUMNS} for r in runs], columns=list(SWEEP_COLUMNS))


def seed_sweep_markdown(df: pd.DataFrame, profile: str) -> str:
    metrics = ("auroc", "ap", "fg_iou", "bg_iou", "chance")
    rows = []
    for config, g in df.groupby("config", sort=False):
        rows.append([f"{config} ({CONFIG_TITLES.get(config, config)}), ours, {len(g)} seeds"]
                    + [pm_seeds(g[m]) + f" ({g[m].min():.4f}–{g[m].max():.4f})" for m in metrics])
        if config in SEED_SWEEP:
            rows.append([f"{config}, paper, 5 seeds"] + [pm(*SEED_SWEEP[config][m], PAPER_DIGITS.get(config, 4))
                                                          for m in metrics])
    return (f"# Seed sweep ({profile} profile): mean ± sample std (min–max)\n\n"
            + markdown(["Config", "AUROC", "AP", "FG IoU", "BG IoU", "Chance"], rows))


def table4_markers(runs: list[dict]) -> pd.DataFrame:
    """Best-of-five per configuration: highest AP, AUROC breaking ties."""
    by_config: dict[str, list] = {}
    for r in runs:
        by_config.setdefault(r["config"], []).append(r)
    best = [best_of_five(rs) for rs in by_config.values()]
    return pd.DataFrame([{k: b[k] for k in TABLE4_COLUMNS} for b in best], columns=list(TABLE4_COLUMNS))


def table4_markers_markdown(df: pd.DataFrame, profile: str) -> str:
    cols = ("tp", "fp", "fn", "tn", "mcc", "f1", "precision", "recall", "fg_iou", "bg_iou", "ap")
    fmt = lambda k, v: str(int(v)) if k in ("tp", "fp", "fn", "tn") else f"{v:.2f}"  # noqa: E731
    rows = []
    for _, r in df.iterrows():
        title = CONFIG_TITLES.get(r["config"], r["config"])
        rows.append([f"{title} ({int(r['seed'])}), ours"] + [fmt(k, r[k]) for k in cols])
        if r["config"] in TABLE4:
            p = TABLE4[r["config"]]
            rows.append([f"{title} ({p['seed']}), paper"] + [fmt(k, p[k]) for k in cols])
    return (f"# Table 4, upper half ({profile} profile): per marker, threshold 0.5, best-of-five by AP\n\n"
            + markdown(["Model (seed)", "TP", "FP", "FN", "TN", "MCC", "F1", "Prec", "Rec", "FG", "BG", "AP"], rows))


def clip_len_ablation(runs: list[dict]) -> pd.DataFrame:
    return pd.DataFrame([{k: r[k] for k in ABLATION_COLUMNS} | {"auroc": r["auroc"]} for r in runs])


def table3_markdown(df: pd.DataFrame, profile: str) -> str:
    rows = []
    for clip_len, g in df.groupby("clip_len"):
        rows.append([f"{clip_len}, ours ({len(g)} seeds)",
                     pm_seeds(g["fg_iou"]) + f" ({g['fg_iou'].min():.4f}–{g['fg_iou'].max():.4f})",
                     pm_seeds(g["auroc"]), pm_seeds(g["ap"])])
        if clip_len in TABLE3:
            p = TABLE3[clip_len]
            rows.append([f"{clip_len}, paper (3 seeds)",
                         pm(*p["fg_iou"]) + f" ({p['fg_range'][0]:.4f}–{p['fg_range'][1]:.4f})",
                         pm(*p["auroc"]), pm(*p["ap"])])
    return (f"# Table 3 ({profile} profile): clip length, A-to-B, mean ± sample std\n\n"
            + markdown(["L", "FG IoU (range)", "AUROC", "AP"], rows))


def table4_maps_row(config: str, op, stats: dict) -> dict:
    """One row of Table 4 lower half from a configuration's operating point and map statistics."""
    r0 = stats["r0"]
    return {"config": config, "threshold": op.threshold, "threshold_rule": op.rule,
            **{k: r0[k] for k in ("tp", "fp", "fn", "tn", "mcc", "f1", "precision", "recall", "fg_iou", "bg_iou",
                                  "ap")},
            "d_bar_mm": stats["d_bar_mm"]}


def table4_maps(rows: list[dict]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=list(MAPS_COLUMNS))


def _maps_cells(v: dict) -> str:
    """Counts with thousands separators, rates at 2 d.p., d-bar in bold, the threshold at 4 d.p."""
    return (" | ".join(num(v[k], 0) for k in COUNTS) + " | "
            + " | ".join(num(v[k], 2) for k in ("mcc", "f1", "precision", "recall", "fg_iou", "bg_iou", "ap"))
            + f" | **{num(v['d_bar_mm'], 2)}** | {num(v['threshold'], 4)} | {v['threshold_rule']} |")


def table4_maps_markdown(df: pd.DataFrame, profile: str, notes: list[str] | None = None,
                         photo: pd.DataFrame | None = None) -> str:
    """Ours and the paper's row by row; d-bar and threshold in bold columns of their own."""
    head = ("| Config | source | TP | FP | FN | TN | MCC | F1 | Prec | Rec | FG | BG | AP | **d̄ mm** | thr | rule |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n")
    lines = []
    for _, r in df.iterrows():
        rows = [("ours", r.to_dict())] + ([("paper", TABLE4_MAPS[r["config"]])] if r["config"] in TABLE4_MAPS else [])
        lines += [f"| {r['config']} | {src} | " + _maps_cells(v) for src, v in rows]
    text = (f"# Table 4, lower half ({profile} profile): vessel map per pixel, exact pixels, operating point "
            f"precision >= 0.9 at 3 mm\n\n" + head + "\n".join(lines) + "\n")
    if photo is not None and len(photo):
        text += "\n## Silicone against the photo truth\n\n" + head
        for _, r in photo.iterrows():
            paper_thr = MAPS_PHOTO_THRESHOLD.get(r["config"].split("/")[0])
            text += f"| {r['config']} | ours | " + _maps_cells(r.to_dict()) + "\n"
            if paper_thr is not None:
                text += f"| {r['config']} | paper | " + " | ".join(["–"] * 12) + f" | {paper_thr:.4f} | |\n"
    if notes:
        text += "\n" + "\n".join(f"* {n}" for n in notes) + "\n"
    return text


# ---- issue 15: the recipe ablation and the ensemble's coverage-precision (docs/results/*.csv) ----
RECIPE_ABLATION_COLUMNS = ("config", "recipe", "switch_off", "seeds", "auroc_mean", "auroc_std", "ap_mean", "ap_std",
                           "pos_share_05", "ece", "d_bar_mm")
UNCERTAINTY_COLUMNS = ("config", "coverage", "precision", "recall")
CROSSFIT_COLUMNS = ("config", "recipe", "switch_off", "calibration", "fitted_on", "seeds", "ece", "ece_std",
                    "pos_share_05", "brier", "ap", "d_bar_mm", "map_recall", "map_pred_px", "map_threshold_from",
                    "d_bar_05_mm", "map_recall_05", "d_bar_05_seeds")


def recipe_ablation(rows: list[dict]) -> pd.DataFrame:
    return pd.DataFrame([{k: r[k] for k in RECIPE_ABLATION_COLUMNS} for r in rows], columns=list(RECIPE_ABLATION_COLUMNS))


def uncertainty_table(rows: list[dict]) -> pd.DataFrame:
    return pd.DataFrame([{k: r[k] for k in UNCERTAINTY_COLUMNS} for r in rows], columns=list(UNCERTAINTY_COLUMNS))


def crossfit_table(rows: list[dict]) -> pd.DataFrame:
    """docs/results/recipe_calibration_crossfit.csv (palpation.apps.recipe_crossfit)."""
    return pd.DataFrame([{k: r[k] for k in CROSSFIT_COLUMNS} for r in rows], columns=list(CROSSFIT_COLUMNS))


def recipe_ablation_markdown(df: pd.DataFrame, profile: str, notes: list[str] | None = None) -> str:
    rows = [[f"{r['config']} ({CONFIG_TITLES.get(r['config'], r['config'])})", r["recipe"], r["switch_off"],
             str(int(r["seeds"])), f"{num(r['auroc_mean'])} ± {num(r['auroc_std'])}",
             f"{num(r['ap_mean'])} ± {num(r['ap_std'])}", f"{100 * r['pos_share_05']:.1f} %", num(r["ece"]),
             num(r["d_bar_mm"], 2)] for _, r in df.iterrows()]
    text = (f"# Training recipe ablation ({profile} profile): mean ± sample std over seeds\n\n"
            + markdown(["Config", "Recipe", "Switch off", "Seeds", "AUROC", "AP", "Positive at 0.5", "ECE",
                        "d̄ (mm)"], rows))
    return text + "".join(f"\n* {n}" for n in notes or []) + ("\n" if notes else "")
