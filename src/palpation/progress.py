"""tqdm progress bars for the long steps, each behind its app's `progress` switch.

A bar only reads counters: it draws no random numbers and leaves the order of the work alone, so
results are the same with it on or off. Snakemake sends stdout/stderr to results/logs/...; into a
file (not a terminal) a bar redraws at most every LOG_INTERVAL_S so that the log stays small.
"""

from __future__ import annotations

import sys
from typing import Iterable

from tqdm.auto import tqdm

LOG_INTERVAL_S = 10.0  # redraw interval when stderr is not a terminal (a log file, a test capture)


def bar(iterable: Iterable | None = None, *, enabled: bool = True, **kwargs) -> tqdm:
    """`tqdm(iterable, **kwargs)`, disabled unless `enabled`; log-friendly when stderr is no terminal."""
    isatty = getattr(sys.stderr, "isatty", None)
    if not (callable(isatty) and isatty()):
        kwargs.setdefault("mininterval", LOG_INTERVAL_S)
    return tqdm(iterable, disable=not enabled, **kwargs)
