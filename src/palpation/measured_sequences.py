"""The measured-sequence format: real slides as marker frames, sensor poses and the scene's vessels.

One set is a file pair (docs/measured_format.md, "Sequences"):
* `<name>.npz`: `markers` (T, F, 127, 2) px, `displacement` = markers - rest, `rest` (127, 2), `found`
  (T, F, 127) bool, `pose_mm` (T, F, 3) tip x, y in the world frame and depth below the phantom top,
  `vessel_points_mm` (P, 2) centreline vertices in the same world frame, `vessel_id` (P,) which vessel
  each vertex belongs to (vertices of one vessel in order along it), optional `labels` (T, F, 127) int8.
* `<name>.json`: format, version, units, world frame, one entry per trial and one per vessel.
A vessel-free scene stores empty vessel arrays; leaving them out is an error, so a set cannot silently
lose its vessels. Marker arrays are checked with the photo format's rules (palpation.measured).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from palpation.io import save_json, save_npz
from palpation.readers import read_json, read_npz
from palpation.markers.lattice import N_MARKERS
from palpation.measured import DISPLACEMENT_TOL_PX

FORMAT_NAME = "palpation.measured_sequences"
FORMAT_VERSION = 1
MARKER_KEYS = ("markers", "displacement", "rest", "found")
REQUIRED_KEYS = (*MARKER_KEYS, "pose_mm", "vessel_points_mm", "vessel_id")
OPTIONAL_KEYS = ("labels",)
FIX = "re-save it with palpation.measured_sequences.save_sequence_set (docs/measured_format.md)"


@dataclass
class SequenceSet:
    """T measured slides of F frames each over one scene with V vessels."""

    markers: np.ndarray  # (T, F, 127, 2) float32 px
    displacement: np.ndarray  # (T, F, 127, 2) float32 px, markers - rest
    rest: np.ndarray  # (127, 2) float32 px
    found: np.ndarray  # (T, F, 127) bool
    pose_mm: np.ndarray  # (T, F, 3) float64: tip x, y (world mm), depth below the phantom top (mm)
    vessel_points_mm: np.ndarray  # (P, 2) float64 world mm
    vessel_id: np.ndarray  # (P,) int32, 0..V-1
    trials: list[dict]  # one per slide: name, source (free-form provenance)
    vessels: list[dict]  # one per vessel: id, diameter_mm (null if unknown), source
    labels: np.ndarray | None = None  # (T, F, 127) int8, 1 = over a vessel (the data's own annotation)
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n_trials(self) -> int:
        return self.markers.shape[0]

    @property
    def n_frames(self) -> int:
        return self.markers.shape[1]

    def centrelines(self) -> list[np.ndarray]:
        """Each vessel's centreline as an (k, 2) polyline in world mm, in vessel-id order."""
        return [self.vessel_points_mm[self.vessel_id == v] for v in range(len(self.vessels))]

    def subset(self, trials) -> "SequenceSet":
        """The same scene with only `trials` (indices), e.g. one fold."""
        idx = np.asarray(list(trials), int)
        return SequenceSet(self.markers[idx], self.displacement[idx], self.rest, self.found[idx], self.pose_mm[idx],
                           self.vessel_points_mm, self.vessel_id, [self.trials[i] for i in idx], self.vessels,
                           None if self.labels is None else self.labels[idx], dict(self.meta))


def make_sequence_set(markers, found, rest, pose_mm, centrelines: list[np.ndarray], trials: list[dict],
                      diameters_mm: list[float | None] | None = None, labels=None, **meta: Any) -> SequenceSet:
    """Build a set from ordered markers, poses and vessel polylines; the displacement is computed here."""
    markers = np.asarray(markers, np.float32)
    rest = np.asarray(rest, np.float32)
    lines = [np.asarray(c, np.float64).reshape(-1, 2) for c in centrelines]
    diameters = list(diameters_mm) if diameters_mm is not None else [None] * len(lines)
    if len(diameters) != len(lines):
        raise ValueError(f"make_sequence_set: {len(lines)} centrelines but {len(diameters)} diameters")
    points = np.concatenate(lines) if lines else np.zeros((0, 2))
    ids = np.concatenate([np.full(len(c), v, np.int32) for v, c in enumerate(lines)]) if lines else np.zeros(0, np.int32)
    vessels = [{"id": v, "diameter_mm": None if d is None else float(d), "source": meta.get("vessel_source", "")}
               for v, d in enumerate(diameters)]
    return SequenceSet(markers, (markers - rest[None, None]).astype(np.float32), rest, np.asarray(found, bool),
                       np.asarray(pose_mm, np.float64), points, ids, list(trials), vessels,
                       None if labels is None else np.asarray(labels, np.int8), dict(meta))


def _paths(path) -> tuple[Path, Path]:
    stem = Path(path)
    if stem.suffix in {".npz", ".json"}:
        stem = stem.with_suffix("")
    return stem.with_name(stem.name + ".npz"), stem.with_name(stem.name + ".json")


def _check_arrays(a: dict[str, np.ndarray], where: Path) -> None:
    missing = [k for k in REQUIRED_KEYS if k not in a]
    if {"vessel_points_mm", "vessel_id"} & set(missing):
        raise ValueError(f"{where}: no vessel geometry (vessel_points_mm, vessel_id); add the scene's vessel "
                         "centrelines in the poses' world frame (empty (0, 2) / (0,) arrays for a vessel-free "
                         "scene) and " + FIX)
    extra = sorted(set(a) - set(REQUIRED_KEYS) - set(OPTIONAL_KEYS))
    if missing or extra:
        raise ValueError(f"{where}: missing keys {missing}, unknown keys {extra}; a sequence set has "
                         f"{list(REQUIRED_KEYS)} and optionally {list(OPTIONAL_KEYS)}; " + FIX)
    m = np.asarray(a["markers"])
    if m.ndim != 4 or m.shape[2:] != (N_MARKERS, 2):
        raise ValueError(f"{where}: markers has shape {m.shape}, expected (trials, frames, {N_MARKERS}, 2) in "
                         "base-graph order (palpation.markers.order)")
    t, f = m.shape[:2]
    shapes = {"displacement": m.shape, "rest": (N_MARKERS, 2), "found": (t, f, N_MARKERS), "labels": (t, f, N_MARKERS)}
    for key, shape in shapes.items():
        if key in a and a[key].shape != shape:
            raise ValueError(f"{where}: {key} has shape {a[key].shape}, expected {shape}")
    pose = np.asarray(a["pose_mm"])
    if pose.ndim != 3 or pose.shape[2] != 3:
        raise ValueError(f"{where}: pose_mm has shape {pose.shape}, expected (trials, frames, 3): tip x, y mm "
                         "and depth mm below the phantom top")
    if pose.shape[:2] != (t, f):
        raise ValueError(f"{where}: pose_mm has {pose.shape[0]} trials x {pose.shape[1]} frames but markers has "
                         f"{t} x {f}; give one pose per marker frame")
    for key in ("markers", "displacement", "rest", "pose_mm", "vessel_points_mm"):
        if not np.issubdtype(a[key].dtype, np.floating) or not np.all(np.isfinite(a[key])):
            raise ValueError(f"{where}: {key} must be finite floats (dtype {a[key].dtype}); fill missing markers "
                             "(found=False) and poses before saving")
    if a["found"].dtype != bool:
        raise ValueError(f"{where}: found has dtype {a['found'].dtype}, expected bool")
    err = np.abs(a["displacement"].astype(np.float64) - (m.astype(np.float64) - a["rest"])).max(initial=0.0)
    if err > DISPLACEMENT_TOL_PX:
        raise ValueError(f"{where}: displacement differs from markers - rest by up to {err:.3g} px; recompute it")
    pts, ids = np.asarray(a["vessel_points_mm"]), np.asarray(a["vessel_id"])
    if pts.ndim != 2 or pts.shape[1] != 2 or ids.shape != (len(pts),) or not np.issubdtype(ids.dtype, np.integer):
        raise ValueError(f"{where}: vessel_points_mm {pts.shape} / vessel_id {ids.shape} {ids.dtype}: expected "
                         "(P, 2) floats and (P,) integers")


def _check_meta(meta: Any, a: dict[str, np.ndarray], where: Path) -> None:
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise ValueError(f"{where}: not a sequence-set metadata file (format != '{FORMAT_NAME}'); "
                         "see docs/measured_format.md")
    if meta.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{where}: format_version {meta.get('format_version')!r} is not supported (this code "
                         f"reads {FORMAT_VERSION}); " + FIX)
    trials, vessels = meta.get("trials"), meta.get("vessels")
    if not isinstance(trials, list) or len(trials) != a["markers"].shape[0]:
        raise ValueError(f"{where}: 'trials' must list one entry per trial of the npz "
                         f"({a['markers'].shape[0]}); got {None if trials is None else len(trials)}")
    if not all(isinstance(t, dict) and "name" in t for t in trials):
        raise ValueError(f"{where}: every trial entry needs a 'name'")
    if not isinstance(vessels, list):
        raise ValueError(f"{where}: 'vessels' is missing; list one entry per vessel ([] for a vessel-free scene)")
    ids = np.asarray(a["vessel_id"])
    if len(ids) and (ids.min() < 0 or ids.max() >= len(vessels)):
        raise ValueError(f"{where}: vessel_id runs {ids.min()}..{ids.max()} but 'vessels' lists {len(vessels)}; "
                         "number the vessels 0..V-1")
    for v, entry in enumerate(vessels):
        if not np.sum(ids == v) >= 2:
            raise ValueError(f"{where}: vessel {v} has fewer than 2 centreline points in vessel_points_mm; "
                             "give each listed vessel a polyline")
        d = entry.get("diameter_mm") if isinstance(entry, dict) else "bad"
        if d is not None and (isinstance(d, bool) or not isinstance(d, (int, float)) or not d > 0):
            raise ValueError(f"{where}: vessel {v} has diameter_mm={d!r}; use a positive number or null")


def _metadata(s: SequenceSet) -> dict[str, Any]:
    meta = {k: v for k, v in s.meta.items() if k not in {"format", "format_version", "trials", "vessels"}}
    meta.setdefault("units", {"markers": "px", "pose_mm": "mm (x, y world; depth below the phantom top)",
                              "vessel_points_mm": "mm (world x, y)", "mm_per_px": 2.0 / 55.0})
    return {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "n_markers": N_MARKERS,
            "n_trials": s.n_trials, "n_frames": s.n_frames, **meta, "trials": s.trials, "vessels": s.vessels}


def _arrays(s: SequenceSet) -> dict[str, np.ndarray]:
    out = {"markers": s.markers, "displacement": s.displacement, "rest": s.rest, "found": s.found,
           "pose_mm": s.pose_mm, "vessel_points_mm": s.vessel_points_mm, "vessel_id": s.vessel_id}
    if s.labels is not None:
        out["labels"] = s.labels
    return {k: np.asarray(v) for k, v in out.items()}


def save_sequence_set(path, s: SequenceSet) -> tuple[Path, Path]:
    """Validate, then write `<path>.npz` and `<path>.json` atomically; returns both paths."""
    npz_path, json_path = _paths(path)
    arrays = _arrays(s)
    _check_arrays(arrays, npz_path)
    meta = json.loads(json.dumps(_metadata(s), default=str))
    _check_meta(meta, arrays, json_path)
    save_npz(npz_path, **arrays)
    save_json(json_path, meta)
    return npz_path, json_path


def load_sequence_set(path) -> SequenceSet:
    """Read and validate a sequence set (`path` with or without .npz/.json)."""
    npz_path, json_path = _paths(path)
    for p in (npz_path, json_path):
        if not p.exists():
            raise FileNotFoundError(f"{p}: missing; a sequence set is a pair <name>.npz + <name>.json "
                                    "(docs/measured_format.md)")
    a = read_npz(npz_path, fix=FIX)
    _check_arrays(a, npz_path)
    meta = read_json(json_path, "fix or re-save it with palpation.measured_sequences.save_sequence_set", kind=dict)
    _check_meta(meta, a, json_path)
    extra = {k: v for k, v in meta.items() if k not in {"format", "format_version", "trials", "vessels"}}
    return SequenceSet(a["markers"].astype(np.float32), a["displacement"].astype(np.float32),
                       a["rest"].astype(np.float32), a["found"].astype(bool), a["pose_mm"].astype(np.float64),
                       a["vessel_points_mm"].astype(np.float64), a["vessel_id"].astype(np.int32), meta["trials"],
                       meta["vessels"], a["labels"].astype(np.int8) if "labels" in a else None, extra)
