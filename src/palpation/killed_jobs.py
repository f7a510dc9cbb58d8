"""Outputs of Snakemake jobs that were killed: `rule all` requests them, so a plain rerun redoes them.

Snakemake marks a job's outputs incomplete when it starts (`.snakemake/incomplete/<base64 path>`) and
unmarks them when it ends, and it deletes existing outputs before running a job. A job killed hard
leaves the marks, and `--rerun-incomplete` redoes it, but only if one of its outputs *exists*: after a
forced rerun (`snakemake -f results/train/.../metrics.json`) is killed, the outputs are gone and the
downstream outputs (the report) are still present and newer than everything they read, so Snakemake
treats the missing files as deleted intermediates and says "Nothing to be done". Requesting the missing
marked outputs from `rule all` makes Snakemake build them again, and the downstream jobs then rerun on
their newer inputs.
"""

from __future__ import annotations

import base64
import os
from pathlib import Path

MARKS = Path(".snakemake") / "incomplete"


def marked_incomplete(workdir: str | os.PathLike = ".") -> list[str]:
    """Paths (as Snakemake wrote them) whose job started and never finished."""
    root = Path(workdir) / MARKS
    paths = []
    for folder, _, names in os.walk(root):
        rel = Path(folder).relative_to(root).parts  # long names are cut into '@'-prefixed folders
        for name in names:
            b64 = "".join(p.removeprefix("@") for p in rel) + name
            try:
                paths.append(base64.urlsafe_b64decode(b64.encode()).decode())
            except (ValueError, UnicodeDecodeError):  # not a mark (e.g. migration_underway)
                continue
    return sorted(paths)


def killed_outputs(workdir: str | os.PathLike = ".") -> list[str]:
    """The marked outputs that are missing: a killed job's, to be requested again."""
    return [p for p in marked_incomplete(workdir)
            if not os.path.isabs(p) and not (Path(workdir) / p).exists()]
