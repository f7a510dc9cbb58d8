"""tqdm progress bars for the long steps, each behind its app's `progress` switch.

A bar only reads counters: it draws no random numbers and leaves the order of the work alone, so
results are the same with it on or off. Snakemake sends stdout/stderr to results/logs/...; into a
file (not a terminal) a bar becomes plain lines, one at most every LOG_INTERVAL_S and one at the end,
without the carriage returns and cursor codes that a terminal bar redraws with.
"""

from __future__ import annotations

import sys
from typing import Iterable

from tqdm.auto import tqdm

LOG_INTERVAL_S = 10.0  # line interval when stderr is not a terminal (a log file, a test capture)


class LineProgress(tqdm):
    """A tqdm bar that writes each refresh as its own line (for log files).

    A refresh ends the previous line and writes the new one; tqdm's close() ends the last (hence
    `leave` is always on: a log keeps every line).
    """

    def __init__(self, *args, **kwargs):
        self._lines = 0
        super().__init__(*args, **{**kwargs, "leave": True})

    def display(self, msg: str | None = None, pos: int | None = None) -> bool:
        self.fp.write(("\n" if self._lines else "") + (msg or self.__str__()))
        self.fp.flush()
        self._lines += 1
        return True


def bar(iterable: Iterable | None = None, *, enabled: bool = True, **kwargs) -> tqdm:
    """`tqdm(iterable, **kwargs)`, disabled unless `enabled`; plain lines when stderr is no terminal."""
    isatty = getattr(sys.stderr, "isatty", None)
    if callable(isatty) and isatty():
        return tqdm(iterable, disable=not enabled, **kwargs)
    kwargs.setdefault("mininterval", LOG_INTERVAL_S)
    return LineProgress(iterable, disable=not enabled, ascii=True, **kwargs)
