"""One npz per simulated trajectory plus a JSON manifest (format: docs/sim_format.md).

Both are written atomically, so a killed batch leaves either complete files or none. A failed
environment never gets a trajectory file: it is listed under `failed` in the manifest with its
parameters, so nothing diverged can be mistaken for data.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from palpation.io import atomic_path, hard_link, save_json, save_npz
from palpation.readers import read_json, read_npz

FORMAT = "palpation-sim/1"
KEYS = ("markers", "labels", "centreline_px", "contact", "T_BA", "frame_index", "centreline_A",
        "rest_markers_px", "params", "seed", "kind", "format")


@dataclass
class TrajectoryRecord:
    """The recorded frames of one environment (F = recorded frames)."""

    name: str  # file stem, e.g. trajectory_0000
    kind: str
    seed: int
    params: dict  # E (Pa), k_n (N/m), c_n, heading_deg, heading_offset_deg, vessel, ... (JSON-able)
    markers: np.ndarray  # (F, 127, 2) float32 px
    labels: np.ndarray  # (F, 127) int8
    centreline_px: np.ndarray  # (F, 50, 2) float32 px
    contact: np.ndarray  # (F,) bool
    T_BA: np.ndarray  # (F, 4, 4) float64, metres
    frame_index: np.ndarray  # (F,) int32, simulated frame index of each recorded frame
    centreline_A: np.ndarray  # (50, 3) float64, metres, world frame
    rest_markers_px: np.ndarray  # (127, 2) float32, bound markers of the undeformed sensor


@dataclass
class FailedRecord:
    name: str
    kind: str
    seed: int
    params: dict
    detected_at_frame: int  # the host read that saw the flag (every 20 frames and at the env's end)
    reason: str = "diverged or inverted element"


@dataclass
class Manifest:
    files: list[dict] = field(default_factory=list)
    failed: list[dict] = field(default_factory=list)
    meta: dict = field(default_factory=dict)


def save_trajectory(path: str | os.PathLike, rec: TrajectoryRecord) -> Path:
    F = len(rec.markers)
    shapes = {"markers": (F, 127, 2), "labels": (F, 127), "centreline_px": (F, 50, 2), "contact": (F,),
              "T_BA": (F, 4, 4), "frame_index": (F,)}
    for key, shape in shapes.items():
        if np.shape(getattr(rec, key)) != shape:
            raise ValueError(f"{rec.name}: `{key}` has shape {np.shape(getattr(rec, key))}, expected {shape}")
    save_npz(path, markers=rec.markers.astype(np.float32), labels=rec.labels.astype(np.int8),
             centreline_px=rec.centreline_px.astype(np.float32), contact=rec.contact.astype(bool),
             T_BA=rec.T_BA.astype(np.float64), frame_index=rec.frame_index.astype(np.int32),
             centreline_A=rec.centreline_A.astype(np.float64),
             rest_markers_px=rec.rest_markers_px.astype(np.float32),
             params=np.array(json.dumps(rec.params, sort_keys=True)), seed=np.int64(rec.seed),
             kind=np.array(rec.kind), format=np.array(FORMAT))
    return Path(path)


def load_trajectory(path: str | os.PathLike) -> dict:
    """Read a trajectory file back into a dict of arrays; `params` is decoded from JSON."""
    fix = f"not a complete {FORMAT} trajectory file: rerun the simulate stage"
    out = read_npz(path, KEYS, fix, finite=("markers", "centreline_px", "T_BA"),
                   shapes={"markers": (None, 127, 2), "labels": (None, 127), "params": (), "kind": (), "seed": ()},
                   dtypes={"params": "U", "kind": "U", "format": "U", "seed": "iu"})
    try:
        out["params"] = json.loads(str(out["params"]))
    except ValueError as exc:
        raise ValueError(f"{path}: `params` is not valid JSON ({exc}); {fix}") from None
    out["kind"], out["format"], out["seed"] = str(out["kind"]), str(out["format"]), int(out["seed"])
    return out


SIM_FIX = "rerun the simulate_dataset rule (palpation.apps.simulate) to rewrite the set"


def read_sim_manifest(path: str | os.PathLike, fix: str = SIM_FIX,
                      allow_empty: bool = False) -> tuple[dict, list[Path]]:
    """(the manifest's mapping, the trajectory files its rows name, in order), every row checked.

    Rows live under `files` (write_outputs: {file, kind, seed, params, ...}) or `trajectories` (plain names,
    graph.synthetic); a bare list of rows is read too. A row without a file name, of an unknown kind or with
    non-mapping params, and a listed file that is gone, are refused naming the row; so is a manifest listing
    no file at all (every trajectory of the run diverged) unless `allow_empty`."""
    from palpation.twin.trajectory import KINDS

    path = Path(path)
    meta = read_json(path, fix, "Sim manifest", kind=(dict, list))
    meta = {"files": meta} if isinstance(meta, list) else meta
    key = "trajectories" if "trajectories" in meta else "files"
    rows = meta.get(key)
    if not isinstance(rows, list) or (not rows and not allow_empty):
        failed = meta.get("failed") if isinstance(meta.get("failed"), list) else []
        raise ValueError(f"Sim manifest {path} lists no trajectory files ({len(failed)} failed); {fix} (check its "
                         "log for diverged environments)")
    files = []
    for i, row in enumerate(rows, start=1):
        name = row if isinstance(row, str) else row.get("file", row.get("path")) if isinstance(row, dict) else None
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"Sim manifest {path}: {key} row {i} ({str(row)[:60]!r}) names no trajectory file; {fix}")
        if isinstance(row, dict) and "kind" in row and row["kind"] not in KINDS:
            raise ValueError(f"Sim manifest {path}: {key} row {i} ({name!r}) has kind {row['kind']!r}, not one of "
                             f"{', '.join(KINDS)}; {fix}")
        if isinstance(row, dict) and not isinstance(row.get("params", {}), dict):
            raise ValueError(f"Sim manifest {path}: {key} row {i} ({name!r}) has params {str(row['params'])[:40]!r}, "
                             f"not a mapping; {fix}")
        files.append(path.parent / name)
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise FileNotFoundError(f"Sim manifest {path}: trajectory files missing: {missing[:3]}; {fix}")
    return meta, files


def previous_files(out_dir: Path, manifest: Path) -> list[Path]:
    """Trajectory files of an earlier run in `out_dir`: those its manifest lists, and every npz of this
    format (Snakemake deletes a rule's declared manifest before rerunning it, not the trajectories)."""
    try:
        listed = [out_dir / Path(e["file"]).name for e in json.loads(manifest.read_text()).get("files", [])]
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        listed = []
    return sorted(set(listed) | {p for p in out_dir.glob("*.npz") if _is_trajectory(p)})


def _is_trajectory(path: Path) -> bool:
    try:
        with np.load(path, allow_pickle=False) as z:
            return "format" in z.files and str(z["format"]) == FORMAT
    except Exception:  # unreadable (a truncated file of a killed writer): not ours to judge, left alone
        return False


def write_outputs(out_dir: str | os.PathLike, records: list[TrajectoryRecord],
                  failed: list[FailedRecord], meta: dict | None = None,
                  manifest_name: str = "manifest.json") -> Path:
    """Write every trajectory file, then the manifest (last, so it only lists files that exist).

    A rerun into the same folder first removes the previous manifest and run's trajectories, so none
    is left beside the new ones (and readers use only the manifest's files anyway)."""
    out_dir = Path(out_dir)
    path = _clear(out_dir, manifest_name, {f"{rec.name}.npz" for rec in records})
    manifest = Manifest(meta={"format": FORMAT, **(meta or {})})
    for rec in records:
        save_trajectory(out_dir / f"{rec.name}.npz", rec)
        manifest.files.append({"file": f"{rec.name}.npz", "kind": rec.kind, "seed": rec.seed,
                               "params": rec.params, "n_frames": int(len(rec.markers)),
                               "positive_rate": float(rec.labels.mean())})
    for bad in failed:
        manifest.failed.append(vars(bad).copy())
    save_json(path, {"files": manifest.files, "failed": manifest.failed, **manifest.meta})
    return path


def copy_outputs(src_manifest: str | os.PathLike, out_dir: str | os.PathLike, meta: dict,
                 manifest_name: str = "manifest.json") -> Path:
    """Copy a finished set (its manifest's files) into `out_dir` with the same discipline as write_outputs: the
    earlier run's files cleared first, each file written whole, the manifest last, its meta updated by `meta`.
    A file is hard-linked where the file system allows it (io.hard_link): sets are only ever rewritten by renaming
    new files into place, so a later run of either set leaves the other's files as they were."""
    src_manifest = Path(src_manifest)
    data, files = read_sim_manifest(src_manifest)
    out_dir = Path(out_dir)
    path = _clear(out_dir, manifest_name, {f.name for f in files})
    for src in files:
        with atomic_path(out_dir / src.name) as tmp:
            if not hard_link(src, tmp):
                shutil.copyfile(src, tmp)
    save_json(path, {**data, **meta})
    return path


def _clear(out_dir: Path, manifest_name: str, new_names: set[str]) -> Path:
    """Remove the manifest, then the earlier run's trajectories not about to be rewritten; returns the manifest path."""
    path = out_dir / manifest_name
    old = previous_files(out_dir, path)
    path.unlink(missing_ok=True)  # first: a run killed below leaves no manifest naming stale files
    for stale in old:
        if stale.name not in new_names:
            stale.unlink(missing_ok=True)
    return path
