"""Results-page section of the recipe ablation (issue 15): reference vs robust (and robust minus each
switch), with the issue's aims for the robust recipe checked and, where missed, by how much."""

from __future__ import annotations

import math

import pandas as pd

from palpation.report.compare import TITLES, Section, aim_lines, aim_miss, compare
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


def sweep_mismatch(df: pd.DataFrame, sweep: pd.DataFrame | None, k: float = 2.0) -> list[str]:
    """The ablation's reference rows against the seed sweep's runs of the same recipe and configuration: AP apart by
    more than k combined seed stds means the two tables were not trained on the same Sim set (or sizes), so this
    table's rows compare with each other, not with the tables above it."""
    if sweep is None or "ap" not in sweep.columns:
        return []
    out = []
    for _, r in df[(df["recipe"] == "reference") & (df["switch_off"] == "none")].iterrows():
        theirs = sweep.loc[sweep["config"] == r["config"], "ap"]
        if len(theirs) < 2:
            continue
        c = compare(r["ap_mean"], r["ap_std"], theirs.mean(), theirs.std(), k, n_ours=int(r["seeds"]))
        if c.within is False:
            out.append(f"{title(r['config'])}, reference: AP {num(r['ap_mean'])} here vs {num(theirs.mean())} in the "
                       f"seed sweep ({c.verdict()}), the same recipe: this table's runs were not trained on the seed "
                       "sweep's Sim set (or at its sizes), so compare its rows with each other, not with the tables "
                       "above.")
    return out


def recipe_ablation_section(df: pd.DataFrame, report: dict | None = None, sweep: pd.DataFrame | None = None,
                            k: float = 2.0) -> Section:
    """The ablation table; `report` (recipe_report.json) names the rows a partial table leaves out; `sweep` (the
    seed sweep) checks that the reference rows come from the same Sim set as the main tables."""
    rows = [[title(r["config"]), r["recipe"], r["switch_off"], int(r["seeds"]),
             f"{num(r['auroc_mean'])} ± {num(r['auroc_std'])}", f"{num(r['ap_mean'])} ± {num(r['ap_std'])}",
             f"{100 * r['pos_share_05']:.1f} %", num(r["ece"]), num(r["d_bar_mm"], 2)] for _, r in df.iterrows()]
    bullets, gaps = aim_lines(aim_checks(df), lambda config: f"{title(config)}, robust")
    bullets += sweep_mismatch(df, sweep, k)
    body = ("Mean ± sample std over seeds of the recipe runs (`results/recipe/`). `switch_off` names the robust "
            "recipe's switch turned back to the reference value (`none`: the full recipe). Positive share at 0.5 "
            "and ECE are computed on the written test scores (calibrated where the recipe calibrates, on the "
            "training domain's validation split); d̄ from each seed's vessel map.\n\n" + partial_text(report)
            + markdown(["Config", "Recipe", "Switch off", "Seeds", "AUROC", "AP", "Positive at 0.5", "ECE", "d̄ (mm)"],
                       rows))
    return Section("recipe_ablation", TITLES["recipe_ablation"], body, bullets, gaps, set(df["config"]))


# --- Cross-fitted calibration between the real sets (rule recipe_crossfit, docs/recipe.md) -------------------
CROSSFIT_FIGURE = "recipe/report/reliability_crossfit.png"
# the rows shown per test set: (switch_off, calibration, label); the last is robust minus `calibration` (raw)
CROSSFIT_ROWS = (("none", "stored", "robust, stored (Platt on the training domain's val split)"),
                 ("none", "cross_real", "robust, **cross_real** (Platt on the other real set)"),
                 ("none", "cross_real_shift", "robust, cross_real_shift (intercept only on the other real set)"),
                 ("none", "in_sample", "robust, in_sample (Platt on the test set itself: a bound, chooses nothing)"),
                 ("calibration", "stored", "robust − `calibration`: the raw scores"))
AP_SAME_TOL = 1e-3  # AP of one model under monotone calibrations: equal up to score ties and float rounding


def _row(cf: pd.DataFrame, config: str, cal: str, switch: str = "none") -> pd.Series | None:
    """The robust row of `config` under calibration `cal` (`switch` off), or None."""
    hit = cf[(cf["config"] == config) & (cf["recipe"] == "robust") & (cf["switch_off"] == switch)
             & (cf["calibration"] == cal)]
    return hit.iloc[0] if len(hit) else None


def _pct(v) -> str:
    return "–" if pd.isna(v) else f"{100 * float(v):.1f} %"


def _d_bar(d, recall, extra: str) -> str:
    return "no pixel" if pd.isna(d) else f"{float(d):.2f} mm (recall {float(recall):.2f}){extra}"


def crossfit_table(cf: pd.DataFrame) -> str:
    """Per test set the robust recipe's calibrations (CROSSFIT_ROWS): ECE, positive share, Brier, both d̄."""
    rows = []
    for config in dict.fromkeys(cf["config"]):
        alone = _no_partner(cf, config)
        for switch, cal, label in CROSSFIT_ROWS:
            if alone and cal in ("cross_real", "cross_real_shift"):
                continue  # nothing to cross-fit on: the stored calibration, repeated
            r = _row(cf, config, cal, switch)
            if r is not None:
                rows.append([title(config), label, r["fitted_on"], f"{num(r['ece'])} ± {num(r['ece_std'])}",
                             _pct(r["pos_share_05"]), num(r["brier"]),
                             _d_bar(r["d_bar_mm"], r["map_recall"], f", threshold from {r['map_threshold_from']}"),
                             _d_bar(r["d_bar_05_mm"], r["map_recall_05"],
                                    f", {int(r['d_bar_05_seeds'])} of {int(r['seeds'])} seeds")])
    return markdown(["Test set", "Scores", "Calibrated on", "ECE", "Positive at 0.5", "Brier",
                     "d̄ at the map threshold", "d̄ at calibrated 0.5"], rows)


def _no_partner(cf: pd.DataFrame, config: str) -> bool:
    """True where the cross_real row calibrates as the stored one (no other real set than the test set)."""
    own, r = _row(cf, config, "stored"), _row(cf, config, "cross_real")
    return own is not None and r is not None and own["fitted_on"] == r["fitted_on"]


def _fmt(col: str, v: float) -> str:
    if col == "pos_share_05":
        return f"{100 * v:.1f} %"
    return f"{v:.2f} mm" if col.startswith("d_bar") else f"{v:.3f}" if col != "ap_std" else f"{v:.4f}"


def _fmt_target(col: str, t: float) -> str:
    return f"{100 * t:g} %" if col == "pos_share_05" else f"{t:g} mm" if col.startswith("d_bar") else f"{t:g}"


def _why(cf: pd.DataFrame, config: str, col: str) -> str:
    """The measured reason an aim is missed, from the same CSVs (the page's known causes add the rest)."""
    if col == "ap":
        aps = cf[(cf["config"] == config) & (cf["recipe"] == "robust") & (cf["switch_off"] == "none")]["ap"]
        if aps.max() - aps.min() <= AP_SAME_TOL:
            return (f"AP is the same under all {len(aps)} calibrations of the row (spread "
                    f"{aps.max() - aps.min():.1g}): calibration changes what the scores mean, not how they rank; "
                    "the ranking is the recipe's")
        return ""
    if col == "ap_std":
        return "AP spread over the Meat-trained seeds; no calibration changes a ranking (recipe ablation table)"
    if col == "ece":
        bound = _row(cf, config, "in_sample")
        if bound is None:
            return ""
        if float(bound["ece"]) <= 0.05:
            return (f"Platt fitted on the test set itself reaches {float(bound['ece']):.3g} (in_sample bound): "
                    "Platt's form is not the limit; the other real set's scores call for another calibration")
        return f"even Platt fitted on the test set itself reaches only {float(bound['ece']):.3g} (in_sample bound)"
    if col == "d_bar_mm":
        own = _row(cf, config, "stored")
        r = _row(cf, config, "cross_real")
        if own is None or r is None:
            return ""
        return (f"the other set's threshold marks {float(r['map_pred_px']):,.0f} pixels against "
                f"{float(own['map_pred_px']):,.0f} at the test map's own (recall {float(r['map_recall']):.2f}): "
                "a map threshold does not carry over between the real sets")
    if col == "d_bar_05_mm":
        r = _row(cf, config, "cross_real")
        return "" if r is None else (f"the closest threshold not chosen on the test set, recall "
                                     f"{float(r['map_recall_05']):.2f} (d̄ alone rewards a high threshold)")
    return ""


def crossfit_checks(cf: pd.DataFrame, ablation: pd.DataFrame | None):
    """(config, column, value, sense, target, miss) of every issue-15 aim under the cross_real calibration;
    the AP std aim from the ablation table (the cross-fit CSV holds means only)."""
    out = []
    for config, col, sense, target in AIMS:
        if col == "ap_std":
            if ablation is not None:
                out += [c for c in aim_checks(ablation) if c[1] == "ap_std" and c[0] == config]
            continue
        cols = {"ap_mean": ["ap"], "d_bar_mm": ["d_bar_mm", "d_bar_05_mm"]}.get(col, [col])
        for c in cols:
            for cfg in ([config] if config else list(dict.fromkeys(cf["config"]))):
                r = _row(cf, cfg, "cross_real")
                if r is None or pd.isna(r[c]):
                    continue
                out.append((cfg, c, float(r[c]), sense, target, aim_miss(float(r[c]), sense, target)))
    return out


COLUMN_WORDS = {"ap": "AP", "ap_std": "AP std over seeds", "pos_share_05": "positive at 0.5", "ece": "ECE",
                "d_bar_mm": "d̄ at the other set's map threshold", "d_bar_05_mm": "d̄ at calibrated 0.5"}


def recipe_crossfit_section(cf: pd.DataFrame, ablation: pd.DataFrame | None = None,
                            report: dict | None = None, figure: str | None = None) -> Section:
    """The robust recipe's scores calibrated on the other real set (recipe_calibration_crossfit.csv), with
    what chose what and every issue-15 aim under it, met or missed by how much and why. `report`:
    recipe_calibration_crossfit.json (the same-model check); `figure`: the link to reliability_crossfit.png."""
    chose = []
    for config in dict.fromkeys(cf["config"]):
        r = _row(cf, config, "cross_real")
        if r is not None:
            alone = (" (no real set other than its test set: nothing to cross-fit, the stored calibration is kept)"
                     if _no_partner(cf, config) else "")
            chose.append(f"* {title(config)}: scores calibrated on {r['fitted_on']}; map threshold from "
                         f"{r['map_threshold_from']}{alone}.")
    same = (report or {}).get("same_model") or {}
    flags = [bool(v) for vs in same.values() for v in vs]
    same_text = (f" Same models: {sum(flags)} of {len(flags)} (row, seed) pairs of the Sim-trained models have "
                 "identical histories on both real sets (`recipe_calibration_crossfit.json`)." if flags else "")
    checks = crossfit_checks(cf, ablation)
    aims = []
    for config, col, v, sense, target, miss in checks:
        state = "met" if miss == 0 else f"**missed by {_fmt(col, miss)}**"
        why = _why(cf, config, col) if miss else ""
        aims.append(f"* {title(config)}: {COLUMN_WORDS.get(col, col)} {_fmt(col, v)} "
                    f"(aim {sense} {_fmt_target(col, target)}): {state}"
                    + (f"; why: {why}." if why else "."))
    _, gaps = aim_lines(checks, title)
    missed = sum(1 for c in checks if c[-1] > 0)
    body = ("Each Sim-trained model's scores on one real set are Platt-calibrated (a·logit + b, a > 0) on the same "
            "model's scores on the other real set, and its map threshold (SPEC §12 rule) is chosen on that set's map "
            "(rule `recipe_crossfit`, docs/recipe.md \"Cross-fitted calibration\"): every figure on a set comes from "
            "parameters chosen on data other than that set. Means (± sample std for ECE) over seeds; robust recipe, "
            "full and minus `calibration`." + same_text + "\n\n"
            "**What chose what**: the Sim val split chose the recipe (its early stopping and stored Platt; the Meat "
            "val trials for the Meat-trained model); the real sets chose each other's calibration and map threshold, "
            "never their own:\n\n" + "\n".join(chose) + "\n\n"
            + crossfit_table(cf)
            + (f"\nReliability per test set: [reliability_crossfit.png]({figure})\n" if figure else "")
            + "\n**Aims of issue 15 under the cross-fitted calibration** (robust recipe; from the CSVs above):\n\n"
            + "\n".join(aims) + "\n")
    bullets = [f"Cross-fitted calibration: {len(checks) - missed} of {len(checks)} aim checks met, {missed} missed "
               "(the section lists by how much and why)."]
    return Section("recipe_crossfit", TITLES["recipe_crossfit"], body, bullets, gaps, set(cf["config"]))
