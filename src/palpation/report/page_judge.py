"""Results-page section "Twin on the task" (issue 12): the candidate twins judged downstream, the choice by
held-out real-slide motion MAE, and the issue's aims checked (where missed, by how much)."""

from __future__ import annotations

import math

import pandas as pd

from palpation.report.compare import TITLES, Section, aim_lines, aim_miss, truthy
from palpation.report.markdown import markdown, num
from palpation.report.twin_selection import TIE_ALPHA, TIE_MIN_GAIN_PX

# (column, sense, target, row): the aims; row "chosen" = the chosen twin's row
AIMS = (("silicone_ap_crossfit", ">=", 0.36, "chosen"), ("meat_ap", ">=", 0.26, "chosen"),
        ("silicone_pos_share_05", "<=", 0.40, "chosen"))
MAE_DROP = 0.30  # the slide-loop twin's held-out MAE >= 30 % below the calibrated twin's


def aim_checks(df: pd.DataFrame) -> list[tuple[str, str, float, str, float, float]]:
    """(twin, column, value, sense, target, miss) of every aim the table can check; miss 0 = met."""
    out = []
    chosen = df[df["chosen"].map(truthy)]
    for col, sense, target, _ in AIMS:
        for _, r in chosen.iterrows():
            v = float(r[col])
            if not math.isnan(v):
                out.append((r["twin"], col, v, sense, target, aim_miss(v, sense, target)))
    by = df.set_index("twin")["heldout_slide_mae_px"].astype(float)
    if {"slide_loop", "calibrated"} <= set(by.index) and by["calibrated"] > 0:
        drop = 1 - by["slide_loop"] / by["calibrated"]
        out.append(("slide_loop", "heldout MAE drop vs calibrated", drop, ">=", MAE_DROP,
                    aim_miss(drop, ">=", MAE_DROP)))
    return out


def slide_loop_rounds(rounds: pd.DataFrame) -> tuple[str, list[str]]:
    """The slide loop's table (per fold and round) and one bullet per fold: held-out MAE first -> last round."""
    gated = "mae_inner_cv_px" in rounds  # the inner gate's columns (slides.loop COLUMNS), absent in older runs
    rows = [[r["fold"], int(r["round"]), r["effect_added"], num(r["mae_fit_px"], 3), num(r["mae_heldout_px"], 3),
             f"{num(r['vessel_ratio_sim'], 2)} / {num(r['vessel_ratio_real'], 2)}"]
            + ([num(r["mae_inner_cv_px"], 3), num(r["gate_p"], 3)] if gated else []) for _, r in rounds.iterrows()]
    bullets = []
    for fold, g in rounds.sort_values("round", kind="stable").groupby("fold", sort=False):
        first, last = float(g["mae_heldout_px"].iloc[0]), float(g["mae_heldout_px"].iloc[-1])
        added = ", ".join(e for e in g["effect_added"].iloc[1:]) or "nothing"
        change = f" ({100 * (last / first - 1):+.0f} %)" if first > 0 else ""
        bounds = str(g["at_bounds"].iloc[-1]) if "at_bounds" in g and g["at_bounds"].notna().iloc[-1] else ""
        bullets.append(f"slide loop, fold {fold}: held-out motion MAE {first:.3f} -> {last:.3f} px{change}; "
                       f"added: {added}." + (f" Symptom: {bounds} (the fit wants more than the physical range; "
                                             "docs/slides.md)." if bounds else ""))
    text = ("\n\nThe slide loop per fold and round (`loop_slides/loop_slides.csv`; each fold fitted on its trials, "
            "scored on the other fold's):\n\n"
            + markdown(["Fold", "Round", "Effect added", "MAE fit (px)", "MAE held-out (px)",
                        "Vessel ratio sim / real (held-out)"]
                       + (["MAE of left-out fold trials (inner gate, px)", "Gate p"] if gated else []), rows))
    return text, bullets


def reachable(df: pd.DataFrame, bounds: pd.DataFrame) -> list[str]:
    """The slide-loop aim read against drift_bounds.csv (slides.diagnosis): the held-out MAE it asks for, what
    predictors without a twin reach, and the bounds that know each held-out trial's own motion."""
    by = df.set_index("twin")["heldout_slide_mae_px"].astype(float)
    if "calibrated" not in by.index or not len(bounds):
        return []
    target = (1 - MAE_DROP) * by["calibrated"]
    b = bounds.set_index("predictor")
    part = lambda names: ", ".join(f"{n.replace('_', ' ')} {b.loc[n, 'heldout_mae_px']:.3f} px "
                                   f"({100 * b.loc[n, 'change_vs_no_motion']:+.1f} %)" for n in names if n in b.index)
    own = [n for n in b.index if truthy(b.loc[n, "uses_heldout_truth"])]
    shared = [n for n in b.index if n not in own and n != "no_motion"]
    text = (f"What the slide-loop aim asks: a held-out MAE <= {target:.3f} px ({100 * MAE_DROP:.0f} % below "
            f"calibrated's {by['calibrated']:.3f}). Without a twin (`judge/drift_bounds.csv`, against no motion "
            f"{b.loc['no_motion', 'heldout_mae_px']:.3f} px): the drift the other fold shares, {part(shared)}; "
            f"bounds that know each held-out trial's own motion: {part(own)}.")
    beyond = [n for n in own if b.loc[n, "heldout_mae_px"] > target]
    if beyond:
        text += (f" Even {', '.join(n.replace('_', ' ') for n in beyond)} misses it: the aim needs more of each held-out "
                 "trial's own motion than its whole-field drift, and what the other fold shares of that drift predicts "
                 "nothing (docs/slides.md, \"What a held-out slide MAE can reach\").")
    return [text]


def twin_selection_section(df: pd.DataFrame, rounds: pd.DataFrame | None = None,
                           bounds: pd.DataFrame | None = None) -> Section:
    rows = [[r["twin"], str(r["fitted_on"]).replace("|", "/"), num(r["heldout_slide_mae_px"], 3),
             f"{num(r['vessel_ratio_sim'], 2)} / {num(r['vessel_ratio_real'], 2)}", num(r["silicone_ap_crossfit"]),
             num(r["silicone_auroc_crossfit"]), num(r["meat_ap"]), num(r["meat_auroc"]),
             f"{100 * float(r['silicone_pos_share_05']):.1f} %", int(r["seeds"]),
             "**yes**" if truthy(r["chosen"]) else ""] for _, r in df.iterrows()]
    bullets, gaps = aim_lines(aim_checks(df), str)
    body = ("Each candidate twin made a Sim set; A-to-B and A-to-C models were trained on it (mean over seeds). "
            "Silicone is cross-fitted: each trial is scored only by models whose twin never saw it (the slide "
            "loop's fold-odd twin scores the even trials and back), pooled over the 10 trials. The held-out slide "
            "MAE is the error of marker motion about each trial's median on real slides the twin was not fitted "
            "on. The choice (no test label is used) keeps the simplest twin (rows top to bottom) unless a more "
            "complex one has a significantly lower held-out MAE, paired by trial (one-sided Wilcoxon signed-rank, "
            f"alpha {TIE_ALPHA:g}), by at least {TIE_MIN_GAIN_PX:g} px per trial on average (`twin_selection.csv` "
            "column `why`). The slide loop keeps an effect only if its fits that "
            "left out a trial of the fitting fold score that trial better (paired test; docs/slides.md). "
            "Figure: `judge/slide_motion.png`.\n\n"
            + markdown(["Twin", "Fitted on", "Held-out slide MAE (px)", "Vessel ratio sim / real",
                        "Silicone AP (x-fit)", "Silicone AUROC (x-fit)", "Meat AP", "Meat AUROC",
                        "Silicone positive at 0.5", "Seeds", "Chosen"], rows))
    if rounds is not None and len(rounds):
        text, fold_bullets = slide_loop_rounds(rounds)
        body += text
        bullets += fold_bullets
    if bounds is not None:
        bullets += reachable(df, bounds)
    return Section("twin_selection", TITLES["twin_selection"], body, bullets, gaps, set(df["twin"]))
