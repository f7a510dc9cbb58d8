"""Results-page sections for the trained models: seed sweep, Table 3, Table 4 (both halves), twin ablation.

Each builder takes the run's tables (read and checked by `compare.read_table`) and returns a Section:
ours | paper | difference, one generated bullet per configuration, and the differences (Gap) that the
explanations' conditions test. Our numbers come only from the tables; the paper's from `paper.py`.
"""

from __future__ import annotations

import math

import pandas as pd

from palpation.report.compare import TITLES, Gap, Section, compare, seed_stats
from palpation.report.markdown import markdown, num, pm, signed
from palpation.report.paper import (CONFIG_TITLES, MAPS_PHOTO_THRESHOLD, MAPS_VIDEO_PHOTO_IOU, PAPER_DIGITS,
                                    SEED_SWEEP, TABLE3, TABLE4, TABLE4_MAPS)

NAMES = {"auroc": "AUROC", "ap": "AP", "fg_iou": "FG IoU", "bg_iou": "BG IoU", "chance": "chance", "mcc": "MCC",
         "f1": "F1", "precision": "Prec", "recall": "Rec", "d_bar_mm": "d̄ mm", "tp": "TP", "fp": "FP",
         "fn": "FN", "tn": "TN"}
SWEEP_METRICS = ("auroc", "ap", "fg_iou", "bg_iou")
COUNTS = ("tp", "fp", "fn", "tn")
RATES = ("mcc", "f1", "precision", "recall", "fg_iou", "bg_iou", "ap")


def title(config: str) -> str:
    return f"{config} ({CONFIG_TITLES[config]})" if config in CONFIG_TITLES else config


def _summary(within: list[str], off: list[str]) -> str:
    parts = []
    if within:
        parts.append("within seed noise: " + ", ".join(within))
    if off:
        parts.append("off: " + "; ".join(off))
    return "; ".join(parts) or "nothing to compare"


def _mean_std_rows(label: str, key: str, g: pd.DataFrame, metrics, paper: dict | None, digits: int, k: float):
    """Rows label | metric | seeds | ours | paper | difference | verdict for mean ± std metrics, and the
    bullet's pieces: metrics within seed noise, metrics off, metrics whose spread is far above the paper's."""
    rows, gaps, within, off, wide = [], [], [], [], []
    for m in metrics:
        mean, std, n = seed_stats(g[m])
        ours = f"{mean:.4f}" if math.isnan(std) else f"{mean:.4f} ± {std:.4f}"
        if paper is None or m not in paper:
            rows.append([label, NAMES[m], n, ours, "–", "–", "not in the paper"])
            continue
        p_mean, p_std = paper[m]
        c = compare(mean, std, p_mean, p_std, k, n_ours=n)
        rows.append([label, NAMES[m], n, ours, pm(p_mean, p_std, digits), signed(c.diff), c.verdict()])
        gaps.append(Gap(key, m, c.diff, c.within))
        if c.within:
            within.append(NAMES[m])
        else:
            z = f", {c.z:.1f}σ" if c.within is False and not math.isnan(c.z) else ""
            off.append(f"{NAMES[m]} {mean:.4f} vs {p_mean:.{digits}f} ({signed(c.diff)}{z})")
        if c.within and p_std > 0 and std > 2 * p_std:
            wide.append(f"{NAMES[m]} {std / p_std:.1f}×")
    return rows, gaps, within, off, wide


def _threshold_behaviour(config: str, g: pd.DataFrame) -> str:
    """Share of all test nodes each seed calls positive at 0.5 (recall · chance / precision): the usual
    reason the IoUs at 0.5 move while the threshold-free AUROC and AP do not."""
    if not {"precision", "recall"} <= set(g.columns):
        return ""
    called = (g["recall"] * g["chance"] / g["precision"].where(g["precision"] > 0)).fillna(0.0)
    none = g.loc[called < 0.01, "seed"].tolist()
    rest = called[called >= 0.01]
    text = ""
    if len(rest):
        lo, hi = f"{rest.min():.0%}", f"{rest.max():.0%}"
        span = lo if lo == hi else f"{lo}–{hi}"
        text = f" At threshold 0.5 the seeds call {span} of all test nodes positive"
        if config in TABLE4:
            t = TABLE4[config]
            text += f" (the paper's best instance: {(t['tp'] + t['fp']) / sum(t[c] for c in COUNTS):.0%})"
    if none:
        text += ("," if text else " At threshold 0.5,") + f" seed(s) {', '.join(map(str, none))} almost none (< 1 %)"
    return text + "." if text else ""


def seed_sweep_section(df: pd.DataFrame, k: float = 2.0) -> Section:
    rows, gaps, bullets = [], [], []
    for config, g in df.groupby("config", sort=False):
        paper = SEED_SWEEP.get(config)
        r, gp, within, off, wide = _mean_std_rows(config, config, g, SWEEP_METRICS, paper,
                                                  PAPER_DIGITS.get(config, 4), k)
        rows += r
        gaps += gp
        if paper is not None:  # the positive rate is a property of the test set, not of the seeds
            chance = float(g["chance"].mean())
            rows.append([config, "chance", len(g), num(chance), num(paper["chance"][0], PAPER_DIGITS.get(config, 4)),
                         signed(chance - paper["chance"][0]), "test-set positive rate (data, not seeds)"])
        spread = (f" Our seed spread is wider than the paper's ({', '.join(wide)} its std), so \"within noise\" "
                  "is a weak statement there." if wide else "")
        bullets.append(f"{title(config)}, {len(g)} seeds: {_summary(within, off)}.{spread}"
                       + _threshold_behaviour(config, g))
    body = (f"Mean ± sample std over seeds (paper: 5 seeds, SPEC §15.1). Difference = ours − paper; "
            f"σ = sqrt(std_ours² + std_paper²); within seed noise = |difference| ≤ {k:g}σ.\n\n"
            + markdown(["Config", "metric", "seeds", "ours", "paper", "ours − paper", "verdict"], rows))
    return Section("seed_sweep", TITLES["seed_sweep"], body, bullets, gaps, set(df["config"]))


def table3_section(df: pd.DataFrame, k: float = 2.0) -> Section:
    metrics = ("fg_iou", "ap") + (("auroc",) if "auroc" in df.columns else ())
    rows, gaps, bullets = [], [], []
    for clip_len, g in df.groupby("clip_len"):
        label = f"{clip_len}"
        r, gp, within, off, _ = _mean_std_rows(label, str(clip_len), g, metrics, TABLE3.get(int(clip_len)), 4, k)
        r[0][3] += f" ({g['fg_iou'].min():.4f}–{g['fg_iou'].max():.4f})"
        if int(clip_len) in TABLE3:
            lo, hi = TABLE3[int(clip_len)]["fg_range"]
            r[0][4] += f" ({lo:.4f}–{hi:.4f})"
        rows += r
        gaps += gp
        bullets.append(f"L = {label}, {len(g)} seeds: {_summary(within, off)}.")
    for m in ("fg_iou", "ap"):  # does the ablation pick the same clip length?
        ours = df.groupby("clip_len")[m].mean()
        paper = {L: v[m][0] for L, v in TABLE3.items() if L in set(ours.index)}
        if paper:
            best_p = max(paper, key=paper.get)
            best_o = int(ours.idxmax())
            same = "the same as" if best_o == best_p else "unlike"
            bullets.append(f"Best mean {NAMES[m]}: ours at L = {best_o}, {same} the paper's L = {best_p}.")
    body = ("Sim→Silicone (A-to-B) trained with clips of L frames; mean ± sample std over seeds, FG IoU with its "
            "min–max (paper: 3 seeds, SPEC §15.4).\n\n"
            + markdown(["L", "metric", "seeds", "ours", "paper", "ours − paper", "verdict"], rows))
    return Section("table3", TITLES["table3"], body, bullets, gaps, {str(v) for v in df["clip_len"]})


def _instance_rows(config: str, ours: dict, paper: dict | None, cols, first: list[str]) -> list[list[str]]:
    rows = [[f"{title(config)}, ours", *first[:1]] + [num(ours[c], 0 if c in COUNTS else 3) for c in cols]]
    if paper is not None:
        rows.append([f"{title(config)}, paper", *first[1:]] + [num(paper[c], 0 if c in COUNTS else 2) for c in cols])
        rows.append(["ours − paper", *([""] * (len(first) - 1))]
                    + [signed(ours[c] - paper[c], 0 if c in COUNTS else 3) for c in cols])
    return rows


def _largest(diffs: dict[str, float], n: int = 3) -> str:
    top = sorted(diffs, key=lambda m: -abs(diffs[m]))[:n]
    return ", ".join(f"{NAMES[m]} {signed(diffs[m], 2)}" for m in top)


def table4_markers_section(df: pd.DataFrame, sweep: pd.DataFrame | None = None, k: float = 2.0) -> Section:
    """Best-of-five per configuration. A single instance has no std of its own: AP and the IoUs are judged
    against the seed sweep's spread (ours and the paper's), the only noise scale there is."""
    rows, gaps, bullets = [], [], []
    for _, r in df.iterrows():
        config, ours = r["config"], r.to_dict()
        paper = TABLE4.get(config)
        rows += _instance_rows(config, ours, paper, COUNTS + RATES,
                               [str(int(ours["seed"])), str(paper["seed"]) if paper else ""])
        if paper is None:
            continue
        judged = []
        for m in RATES:
            std, n = math.nan, None
            if sweep is not None and m in SWEEP_METRICS and config in SEED_SWEEP:
                _, std, n = seed_stats(sweep.loc[sweep["config"] == config, m])
            c = compare(ours[m], std, paper[m], SEED_SWEEP.get(config, {}).get(m, (0, math.nan))[1], k, n_ours=n)
            gaps.append(Gap(config, m, c.diff, c.within))
            if c.within is not None:
                judged.append(f"{NAMES[m]} {c.verdict()}")
        seed = ("the same seed as" if int(ours["seed"]) == paper["seed"] else f"seed {int(ours['seed'])}, not")
        bullets.append(f"{title(config)}: the best instance is {seed} the paper's seed {paper['seed']}; largest "
                       f"differences {_largest({m: ours[m] - paper[m] for m in RATES})}"
                       + (f"; against the seed sweep's spread: {', '.join(judged)}" if judged else "") + ".")
    body = ("Best instance per configuration (highest test AP among the run's seeds; the paper: best of five), "
            "per marker at threshold 0.5 (SPEC §15.5; the paper prints 2 d.p.).\n\n"
            + markdown(["Model", "seed", *[NAMES[c] for c in COUNTS + RATES]], rows))
    return Section("table4_markers", TITLES["table4_markers"], body, bullets, gaps, set(df["config"]))


def table4_maps_section(df: pd.DataFrame, photo: pd.DataFrame | None = None, pose_check: dict | None = None) -> Section:
    cols = COUNTS + RATES + ("d_bar_mm",)
    rows, gaps, bullets = [], [], []
    for _, r in df.iterrows():
        config, ours = r["config"], r.to_dict()
        paper = TABLE4_MAPS.get(config)
        first = [f"{ours['threshold']:.4f} {ours['threshold_rule']}",
                 f"{paper['threshold']:.4f} {paper['threshold_rule']}" if paper else ""]
        rows += _instance_rows(config, ours, paper, cols, first)
        if paper is None:
            continue
        gaps += [Gap(config, m, ours[m] - paper[m], None) for m in cols]
        rule = ("the same threshold rule" if ours["threshold_rule"] == paper["threshold_rule"] else
                f"threshold rule {ours['threshold_rule']} where the paper has {paper['threshold_rule']}")
        bullets.append(f"{title(config)}: d̄ {ours['d_bar_mm']:.2f} vs {paper['d_bar_mm']:.2f} mm "
                       f"({signed(ours['d_bar_mm'] - paper['d_bar_mm'], 2)}), {rule}; largest other differences "
                       f"{_largest({m: ours[m] - paper[m] for m in RATES})}.")
    both = [c for c in df["config"] if c in TABLE4_MAPS]
    if both:
        ours_d = df.set_index("config").loc[both, "d_bar_mm"]
        paper_d = pd.Series({c: TABLE4_MAPS[c]["d_bar_mm"] for c in both})
        rest = [c for c in both if c != "A-to-C"]
        without = (f" ({ours_d[rest].min():.2f}–{ours_d[rest].max():.2f} vs {paper_d[rest].min():.2f}–"
                   f"{paper_d[rest].max():.2f} without Sim→Meat)" if rest and len(rest) < len(both) else "")
        bullets.append(f"d̄ range: ours {ours_d.min():.2f}–{ours_d.max():.2f} mm vs the paper's "
                       f"{paper_d.min():.2f}–{paper_d.max():.2f} mm{without}.")
    body = ("Vessel map per pixel at each model's operating point, exact pixels (SPEC §12, §15.6). The second "
            "column is the threshold and the rule that chose it (precision ≥ 0.9 at 3 mm, else the F1 "
            "optimum).\n\n" + markdown(["Model", "thr, rule", *[NAMES[c] for c in cols]], rows))
    if photo is not None:
        prow = []
        for _, r in photo.iterrows():
            base = r["config"].split("/")[0]
            paper_thr = MAPS_PHOTO_THRESHOLD.get(base)
            prow.append([title(base), f"{r['threshold']:.4f} {r['threshold_rule']}", num(paper_thr),
                         *[num(r[c], 0) for c in COUNTS], num(r["precision"], 3), num(r["recall"], 3),
                         num(r["d_bar_mm"], 2)])
        body += ("\nSilicone against the photo truth (the paper publishes only the thresholds):\n\n"
                 + markdown(["Model", "ours thr, rule", "paper thr", "TP", "FP", "FN", "TN", "Prec", "Rec",
                             "d̄ mm"], prow))
    iou = ((pose_check or {}).get("check") or {}).get("iou_video_photo")
    if iou is not None:
        body += (f"\nSilicone pose check: video-vs-photo truth IoU {iou:.4f} (paper {MAPS_VIDEO_PHOTO_IOU:.4f}; "
                 "our Silicone poses are reconstructed, see below).\n")
        bullets.append(f"Silicone truth check: video-vs-photo IoU {iou:.4f} vs the paper's "
                       f"{MAPS_VIDEO_PHOTO_IOU:.4f} ({signed(iou - MAPS_VIDEO_PHOTO_IOU)}).")
    return Section("table4_maps", TITLES["table4_maps"], body, bullets, gaps, set(df["config"]))


def twin_ablation_section(df: pd.DataFrame, k: float = 2.0) -> Section:
    """Which twin made the Sim set: the loop's final twin vs the calibrated twin alone (no paper row of
    its own; the paper's seed sweep is the calibrated reference twin)."""
    rows, gaps, bullets = [], [], []
    for exp, g in df.groupby("experiment", sort=False):
        by = {r["dataset_twin"]: r for _, r in g.iterrows()}
        for twin, r in by.items():
            rows.append([title(exp), twin, int(r["n_seeds"]), pm(r["auroc_mean"], r["auroc_std"]),
                         pm(r["ap_mean"], r["ap_std"]), num(r["fg_iou_mean"]), num(r["bg_iou_mean"])])
        paper = SEED_SWEEP.get(exp)
        if paper:
            d = PAPER_DIGITS.get(exp, 4)
            rows.append([title(exp), "paper", 5, pm(*paper["auroc"], d), pm(*paper["ap"], d),
                         num(paper["fg_iou"][0], d), num(paper["bg_iou"][0], d)])
        if {"loop", "calibrated"} <= set(by):
            lo, ca = by["loop"], by["calibrated"]
            seeds = int(min(lo["n_seeds"], ca["n_seeds"]))
            cmp = {m: compare(lo[f"{m}_mean"], lo[f"{m}_std"], ca[f"{m}_mean"], ca[f"{m}_std"], k, n_ours=seeds)
                   for m in ("auroc", "ap")}
            rows.append([title(exp), "loop − calibrated", "", *[f"{signed(c.diff)} ({c.verdict()})"
                                                              for c in cmp.values()],
                         signed(lo["fg_iou_mean"] - ca["fg_iou_mean"]), signed(lo["bg_iou_mean"] - ca["bg_iou_mean"])])
            gaps += [Gap(exp, m, c.diff, c.within) for m, c in cmp.items()]
            bullets.append(f"{title(exp)}: Sim from the loop's twin vs the calibrated twin: "
                           + ", ".join(f"{NAMES[m]} {signed(c.diff)} ({c.verdict()})" for m, c in cmp.items()) + ".")
    body = ("Models trained on a Sim set made by the residual loop's final twin (`loop`, fitted on the flat-tip "
            "photos) or by the calibrated twin alone (`calibrated`); mean ± sample std over seeds. The paper's row is "
            "its seed sweep (SPEC §15.1).\n\n"
            + markdown(["Config", "Sim made by", "seeds", "AUROC", "AP", "FG IoU", "BG IoU"], rows))
    return Section("twin_ablation", TITLES["twin_ablation"], body, bullets, gaps,
                   set(df["experiment"]))
