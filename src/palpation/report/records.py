"""The committed records under docs/results/ as the docs' number generators read them (report.docnumbers)."""

from __future__ import annotations

from pathlib import Path

from palpation.readers import read_csv

FIX = "restore it from git (docs/results/ holds the committed records the docs quote)"


def record_csv(results: Path, name: str, columns: tuple[str, ...]):
    """A record's table with the columns a number needs (a one-line error names the file and the fix)."""
    return read_csv(results / name, columns, fix=FIX, what="record")
