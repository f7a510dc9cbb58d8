"""Atomic writers: an output either exists complete or not at all.

Every file is written to a temporary sibling and renamed into place, so a killed job never
leaves a half-written file that Snakemake or a later reader could take for a finished one. The
temporary name carries the writer's host and pid; a writer killed hard (SIGKILL) leaves its temporary
behind, and the next write of the same path (the rerun of the job) removes it.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import socket
import tempfile
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from palpation.process import pid_alive

_UMASK = os.umask(0)
os.umask(_UMASK)
_HOST = socket.gethostname().replace(".", "_")


def _temp_prefix(path: Path, pid: int | None = None) -> str:
    return f".{path.name}.{_HOST}.{os.getpid() if pid is None else pid}."


def remove_stale_temps(path: str | os.PathLike) -> list[Path]:
    """Delete temporaries of `path` left by dead writers on this host; returns what was deleted."""
    path = Path(path)
    head = f".{path.name}.{_HOST}."
    removed = []
    for tmp in path.parent.glob(f".{path.name}.*"):
        pid = tmp.name[len(head):].split(".")[0] if tmp.name.startswith(head) else ""
        if not pid.isdigit() or pid_alive(int(pid)):
            continue  # not ours, or its writer is alive (or a reused pid): leave it
        tmp.unlink(missing_ok=True)
        removed.append(tmp)
    return removed


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to `path`; rename it onto `path` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=_temp_prefix(path), suffix=suffix or path.suffix)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.chmod(tmp_path, 0o666 & ~_UMASK)  # mkstemp creates 0600; finished files get normal modes
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def save_npz(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez_compressed(tmp, **arrays)


def save_json(path: str | os.PathLike, obj: Any) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n")


def save_text(path: str | os.PathLike, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def csv_text(rows: list[dict], columns, digits: int, na_rep: str | None = None) -> str:
    """CSV of `rows` restricted to `columns`, floats at `digits` decimals; NaN as `na_rep` when given."""
    def cell(v):
        if isinstance(v, float) and na_rep is not None and np.isnan(v):
            return na_rep
        return f"{v:.{digits}f}" if isinstance(v, float) else v

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: cell(r[k]) for k in columns})
    return buf.getvalue()


def save_figure(fig, path_stem: str | os.PathLike, dpi: int = 150) -> list[Path]:
    """Save a matplotlib figure as PNG and PDF (`path_stem` without suffix, or with .png)."""
    stem = Path(path_stem)
    if stem.suffix in {".png", ".pdf"}:
        stem = stem.with_suffix("")
    out = []
    for ext in (".png", ".pdf"):
        target = stem.with_suffix(ext)
        with atomic_path(target) as tmp:
            fig.savefig(tmp, dpi=dpi, format=ext[1:], bbox_inches="tight")
        out.append(target)
    return out


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
