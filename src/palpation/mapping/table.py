"""Table 4, lower half: per-pixel map statistics at the operating point, beside the paper's (SPEC §15.6)."""

from __future__ import annotations

import math
import numbers

import pandas as pd

# SPEC §15.6 (exact pixels, best-of-five); the numbers live with the paper's others
from palpation.report.paper import MAPS_PHOTO_THRESHOLD as PAPER_PHOTO_THRESHOLD
from palpation.report.paper import TABLE4_MAPS as PAPER

COLUMNS = ("config", "threshold", "threshold_rule", "tp", "fp", "fn", "tn", "mcc", "f1", "precision", "recall",
           "fg_iou", "bg_iou", "ap", "d_bar_mm")


def table_row(config: str, op, stats: dict) -> dict:
    r0 = stats["r0"]
    return {"config": config, "threshold": op.threshold, "threshold_rule": op.rule,
            **{k: r0[k] for k in ("tp", "fp", "fn", "tn", "mcc", "f1", "precision", "recall", "fg_iou", "bg_iou",
                                  "ap")},
            "d_bar_mm": stats["d_bar_mm"]}


def table4_maps(rows: list[dict]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=list(COLUMNS))


def _fmt(v, digits: int = 2) -> str:
    if isinstance(v, str):
        return v
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if isinstance(v, numbers.Integral):
        return f"{int(v):,}"
    return f"{float(v):.{digits}f}"


def table4_markdown(df: pd.DataFrame, profile: str, notes: list[str] | None = None,
                    photo: pd.DataFrame | None = None) -> str:
    """Ours and the paper's row by row; d-bar and threshold in bold columns of their own."""
    head = ("| Config | source | TP | FP | FN | TN | MCC | F1 | Prec | Rec | FG | BG | AP | **d̄ mm** | thr | rule |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n")
    lines = []
    for _, r in df.iterrows():
        rows = [("ours", r.to_dict())] + ([("paper", PAPER[r["config"]])] if r["config"] in PAPER else [])
        for src, v in rows:
            lines.append(f"| {r['config']} | {src} | " + " | ".join(_fmt(v[k]) for k in ("tp", "fp", "fn", "tn"))
                         + " | " + " | ".join(_fmt(v[k]) for k in ("mcc", "f1", "precision", "recall", "fg_iou",
                                                                 "bg_iou", "ap"))
                         + f" | **{_fmt(v['d_bar_mm'])}** | {_fmt(v['threshold'], 4)} | {v['threshold_rule']} |")
    text = (f"# Table 4, lower half ({profile} profile): vessel map per pixel, exact pixels, operating point "
            f"precision >= 0.9 at 3 mm\n\n" + head + "\n".join(lines) + "\n")
    if photo is not None and len(photo):
        text += "\n## Silicone against the photo truth\n\n" + head
        for _, r in photo.iterrows():
            v = r.to_dict()
            paper_thr = PAPER_PHOTO_THRESHOLD.get(r["config"].split("/")[0])
            text += (f"| {r['config']} | ours | " + " | ".join(_fmt(v[k]) for k in ("tp", "fp", "fn", "tn")) + " | "
                     + " | ".join(_fmt(v[k]) for k in ("mcc", "f1", "precision", "recall", "fg_iou", "bg_iou", "ap"))
                     + f" | **{_fmt(v['d_bar_mm'])}** | {_fmt(v['threshold'], 4)} | {v['threshold_rule']} |\n")
            if paper_thr is not None:
                text += f"| {r['config']} | paper | " + " | ".join(["–"] * 12) + f" | {paper_thr:.4f} | |\n"
    if notes:
        text += "\n" + "\n".join(f"* {n}" for n in notes) + "\n"
    return text
