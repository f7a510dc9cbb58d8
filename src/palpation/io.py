"""Atomic writers: an output either exists complete or not at all (the checked readers: palpation.readers).

Every file is written to a temporary sibling and renamed into place, so a killed job never
leaves a half-written file that Snakemake or a later reader could take for a finished one. The
temporary name carries the writer's host and pid; a writer killed hard (SIGKILL) leaves its temporary
behind, and the next write of the same path (the rerun of the job) removes it.
"""

from __future__ import annotations

import contextlib
import csv
import errno
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


_WRITE_FIXES = {errno.ENOSPC: "free space on its file system (or move PALPATION_RESULTS elsewhere)",
                errno.EDQUOT: "free space within your quota (or move PALPATION_RESULTS elsewhere)",
                errno.EROFS: "the file system is read-only: set PALPATION_RESULTS to a writable folder",
                errno.EACCES: "make the folder writable, or set PALPATION_RESULTS to a writable folder",
                errno.EPERM: "make the folder writable, or set PALPATION_RESULTS to a writable folder"}


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to `path`; rename it onto `path` only if the block succeeds.

    A failed write (disk full, read-only or foreign folder) raises the same OSError type with a
    one-line message naming `path` and the fix."""
    path = Path(path)
    tmp_path = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temps(path)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=_temp_prefix(path), suffix=suffix or path.suffix)
        os.close(fd)
        tmp_path = Path(tmp)
        yield tmp_path
        os.chmod(tmp_path, 0o666 & ~_UMASK)  # mkstemp creates 0600; finished files get normal modes
        os.replace(tmp_path, path)
    except OSError as exc:
        if exc.errno not in _WRITE_FIXES:
            raise
        raise type(exc)(exc.errno, f"cannot write {path}: {os.strerror(exc.errno)}; "
                                   f"{_WRITE_FIXES[exc.errno]}") from None
    finally:
        if tmp_path is not None and tmp_path.exists():
            tmp_path.unlink()


def hard_link(src: str | os.PathLike, dest: str | os.PathLike) -> bool:
    """Make `dest` (replaced if present) a hard link to `src`; False where links are impossible (another file
    system, or not allowed), `dest` then absent. Safe for files only ever rewritten by renaming a new file into
    place (atomic_path): a later rewrite of either name leaves the other's bytes."""
    dest = Path(dest)
    with contextlib.suppress(FileNotFoundError):
        dest.unlink()
    try:
        os.link(src, dest)
    except OSError:
        return False
    return True


def save_npz(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez_compressed(tmp, **arrays)


def strict_json(obj: Any) -> tuple[Any, list[str]]:
    """`obj` with every NaN/inf float replaced by None (JSON null), and the paths replaced."""
    replaced: list[str] = []

    def clean(v: Any, where: str) -> Any:
        if isinstance(v, dict):
            return {k: clean(x, f"{where}.{k}" if where else str(k)) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x, f"{where}[{i}]") for i, x in enumerate(v)]
        v = _json_default(v) if isinstance(v, (np.generic, np.ndarray, Path)) else v
        if isinstance(v, (list, dict)):
            return clean(v, where)
        if isinstance(v, float) and not np.isfinite(v):
            replaced.append(where)
            return None
        return v

    return clean(obj, ""), replaced


def save_json(path: str | os.PathLike, obj: Any) -> None:
    """Strict JSON (no bare NaN): a non-finite float is written as null and, in a mapping, its path is
    listed under `non_finite` so that a reader can tell a missing value from an undefined one."""
    obj, replaced = strict_json(obj)
    if replaced and isinstance(obj, dict):
        obj["non_finite"] = replaced
    text = json.dumps(obj, indent=2, sort_keys=True, default=_json_default, allow_nan=False) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def save_bytes(path: str | os.PathLike, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


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
