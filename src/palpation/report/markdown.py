"""Markdown cells and tables: the one place numbers are formatted for the tables and the results page."""

from __future__ import annotations

import math

from palpation.metrics.aggregate import summarise_seeds


def markdown(header: list[str], rows: list[list]) -> str:
    """A pipe table of preformatted cells. Not `DataFrame.to_markdown` (tabulate 0.10, checked 2026-11-27): it parses
    "0.7250" back to 0.725, dropping the fixed digits `num` gives, and pads and aligns every column, so every
    committed table and results page would change byte for byte; `disable_numparse=True` keeps the digits, not the
    layout."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def num(v, digits: int = 4) -> str:
    """A number at `digits` d.p.; integers with thousands separators; '–' for missing."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if isinstance(v, str):
        return v
    if float(v).is_integer() and digits == 0:
        return f"{int(v):,}"
    return f"{float(v):.{digits}f}"


def signed(v, digits: int = 4) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if digits == 0:
        return f"{int(round(v)):+,}"
    return f"{float(v):+.{digits}f}"


def pm(mean: float, std: float, digits: int = 4) -> str:
    return num(mean, digits) if (std is None or math.isnan(std) or std == 0) else \
        f"{mean:.{digits}f} ± {std:.{digits}f}"


def pm_seeds(values, digits: int = 4) -> str:
    """Mean ± sample std of per-seed values; '–' for the std of a single seed."""
    s = summarise_seeds(values)
    std = "–" if s["n"] < 2 else f"{s['std']:.{digits}f}"
    return f"{s['mean']:.{digits}f} ± {std}"
