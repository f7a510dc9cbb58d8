"""Results-page section of the recipe ablation (issue 15): reference vs robust (and robust minus each
switch), with the issue's aims for the robust recipe checked and, where missed, by how much."""

from __future__ import annotations

import math

import pandas as pd

from palpation.report.compare import TITLES, Section, aim_lines, aim_miss
from palpation.report.markdown import markdown, num
from palpation.report.page_training import title

# (config or None for every row, column, sense, target): the robust recipe's aims in the issue
AIMS = (("A-to-B", "ap_mean", ">=", 0.40), ("A-to-C", "ap_mean", ">=", 0.30), ("C-to-B", "ap_std", "<=", 0.03),
        (None, "pos_share_05", "<=", 0.30), (None, "ece", "<=", 0.05), ("A-to-C", "d_bar_mm", "<=", 3.0))


def aim_checks(df: pd.DataFrame) -> list[tuple[str, str, float, str, float, float]]:
    """(config, column, value, sense, target, miss) of every aim with a robust full-recipe row; miss 0 = met."""
    robust = df[(df["recipe"] == "robust") & (df["switch_off"] == "none")]
    out = []
    for config, col, sense, target in AIMS:
        for _, r in robust.iterrows():
            if config is not None and r["config"] != config:
                continue
            v = float(r[col])
            if math.isnan(v):
                continue
            out.append((r["config"], col, v, sense, target, aim_miss(v, sense, target)))
    return out


def partial_text(report: dict | None) -> str:
    """The page's note on a partial table (recipe_report partial=true): which rows are left out, and why."""
    left = (report or {}).get("left_out") or []
    if not left:
        return ""
    items = "\n".join(f"* {title(r['config'])}, {r['recipe']}, switch off `{r['switch_off']}`: runs of seeds "
                      f"{', '.join(map(str, r['missing_seeds']))} missing" for r in left)
    why = report.get("partial_reason")
    return (f"**Partial table**: {len(left)} row(s) of the planned ablation are left out because their runs do not "
            "exist (the report's `partial=true`; a row is all its seeds or absent, never a mean of fewer)."
            + (f" Why: {why}" if why else "") + "\n\n" + items + "\n\n")


def recipe_ablation_section(df: pd.DataFrame, report: dict | None = None) -> Section:
    """The ablation table; `report` (recipe_report.json) names the rows a partial table leaves out."""
    rows = [[title(r["config"]), r["recipe"], r["switch_off"], int(r["seeds"]),
             f"{num(r['auroc_mean'])} ± {num(r['auroc_std'])}", f"{num(r['ap_mean'])} ± {num(r['ap_std'])}",
             f"{100 * r['pos_share_05']:.1f} %", num(r["ece"]), num(r["d_bar_mm"], 2)] for _, r in df.iterrows()]
    bullets, gaps = aim_lines(aim_checks(df), lambda config: f"{title(config)}, robust")
    body = ("Mean ± sample std over seeds of the recipe runs (`results/recipe/`). `switch_off` names the robust "
            "recipe's switch turned back to the reference value (`none`: the full recipe). Positive share at 0.5 "
            "and ECE are computed on the written test scores (calibrated where the recipe calibrates, on the "
            "training domain's validation split); d̄ from each seed's vessel map.\n\n" + partial_text(report)
            + markdown(["Config", "Recipe", "Switch off", "Seeds", "AUROC", "AP", "Positive at 0.5", "ECE", "d̄ (mm)"],
                       rows))
    return Section("recipe_ablation", TITLES["recipe_ablation"], body, bullets, gaps, set(df["config"]))
