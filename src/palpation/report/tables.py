"""Seed sweep, Table 4 upper half and Table 3 as CSV frames and Markdown beside the paper (SPEC §15)."""

from __future__ import annotations

import pandas as pd

from palpation.metrics.aggregate import best_of_five, summarise_seeds
from palpation.report.paper import CONFIG_TITLES, PAPER_DIGITS, SEED_SWEEP, TABLE3, TABLE4
from palpation.report.runs import SWEEP_COLUMNS

TABLE4_COLUMNS = ("config", "seed", "tp", "fp", "fn", "tn", "mcc", "f1", "precision", "recall",
                  "fg_iou", "bg_iou", "ap", "auroc")
ABLATION_COLUMNS = ("clip_len", "seed", "fg_iou", "ap")


def markdown(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def pm(values, digits: int = 4) -> str:
    s = summarise_seeds(values)
    std = "–" if s["n"] < 2 else f"{s['std']:.{digits}f}"
    return f"{s['mean']:.{digits}f} ± {std}"


def _paper_pm(mean: float, std: float, digits: int = 4) -> str:
    """The paper's values at the precision it printed them (A-to-A sweep: 3 d.p.; SPEC §15.1)."""
    return f"{mean:.{digits}f}" if std == 0 else f"{mean:.{digits}f} ± {std:.{digits}f}"


def seed_sweep(runs: list[dict]) -> pd.DataFrame:
    return pd.DataFrame([{k: r[k] for k in SWEEP_COLUMNS} for r in runs], columns=list(SWEEP_COLUMNS))


def seed_sweep_markdown(df: pd.DataFrame, profile: str) -> str:
    metrics = ("auroc", "ap", "fg_iou", "bg_iou", "chance")
    rows = []
    for config, g in df.groupby("config", sort=False):
        rows.append([f"{config} ({CONFIG_TITLES.get(config, config)}), ours, {len(g)} seeds"]
                    + [pm(g[m]) + f" ({g[m].min():.4f}–{g[m].max():.4f})" for m in metrics])
        if config in SEED_SWEEP:
            rows.append([f"{config}, paper, 5 seeds"] + [_paper_pm(*SEED_SWEEP[config][m], PAPER_DIGITS.get(config, 4))
                                                          for m in metrics])
    return (f"# Seed sweep ({profile} profile): mean ± sample std (min–max)\n\n"
            + markdown(["Config", "AUROC", "AP", "FG IoU", "BG IoU", "Chance"], rows))


def table4(runs: list[dict]) -> pd.DataFrame:
    """Best-of-five per configuration: highest AP, AUROC breaking ties."""
    by_config: dict[str, list] = {}
    for r in runs:
        by_config.setdefault(r["config"], []).append(r)
    best = [best_of_five(rs) for rs in by_config.values()]
    return pd.DataFrame([{k: b[k] for k in TABLE4_COLUMNS} for b in best], columns=list(TABLE4_COLUMNS))


def table4_markdown(df: pd.DataFrame, profile: str) -> str:
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
                     pm(g["fg_iou"]) + f" ({g['fg_iou'].min():.4f}–{g['fg_iou'].max():.4f})",
                     pm(g["auroc"]), pm(g["ap"])])
        if clip_len in TABLE3:
            p = TABLE3[clip_len]
            rows.append([f"{clip_len}, paper (3 seeds)",
                         _paper_pm(*p["fg_iou"]) + f" ({p['fg_range'][0]:.4f}–{p['fg_range'][1]:.4f})",
                         _paper_pm(*p["auroc"]), _paper_pm(*p["ap"])])
    return (f"# Table 3 ({profile} profile): clip length, A-to-B, mean ± sample std\n\n"
            + markdown(["L", "FG IoU (range)", "AUROC", "AP"], rows))
