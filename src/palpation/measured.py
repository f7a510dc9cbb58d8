"""The measured-marker-set format: ordered real marker positions that calibration and the residual loop read.

One set is a file pair (see docs/measured_format.md):
* `<name>.npz`: `markers` (S, 127, 2) px, `displacement` (S, 127, 2) = markers - rest, `rest` (127, 2),
  `found` (S, 127) bool; markers in base-graph order (SPEC §5.2), float32.
* `<name>.json`: format version, units, camera, detector and one entry per state (name, source file,
  trajectory, depth, angle).
Loading validates everything and fails with one line naming the file, the problem and the fix, so a
user's own set either loads cleanly or says exactly what to change. Nothing is written unless the set
is valid.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from palpation.io import save_json, save_npz
from palpation.readers import read_json, read_npz
from palpation.markers.lattice import N_MARKERS

FORMAT_NAME = "palpation.measured_markers"
FORMAT_VERSION = 1
TRAJECTORIES = ("press", "twist_z", "twist_x", "slide", "rest")
NPZ_KEYS = ("markers", "displacement", "rest", "found")
DISPLACEMENT_TOL_PX = 1e-2  # float32 rounding of markers - rest stays far below this

_NAME_RE = re.compile(r"^(?P<kind>press|twist_z|twist_x|slide)_press_depth=(?P<depth>[-\d.]+)"
                      r"(?:_angle=(?P<angle>[-\d.]+))?(?:_slide_length=(?P<slide>[-\d.]+))?")


@dataclass(frozen=True)
class MeasuredState:
    """One measured state (a photo, or a frame of a sequence)."""

    name: str
    source_file: str
    trajectory: str  # one of TRAJECTORIES
    depth_mm: float | None = None
    angle_deg: float | None = None  # twist angle; None for press, slide and rest


@dataclass
class MeasuredSet:
    """Ordered marker positions of S states and the rest they are measured against."""

    markers: np.ndarray  # (S, 127, 2) float32 px
    displacement: np.ndarray  # (S, 127, 2) float32 px, markers - rest
    rest: np.ndarray  # (127, 2) float32 px
    found: np.ndarray  # (S, 127) bool; False = filled in, not detected
    states: list[MeasuredState]
    meta: dict[str, Any] = field(default_factory=dict)  # units, camera, detector, rest source

    def __len__(self) -> int:
        return len(self.states)

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.states]

    def index(self, name: str) -> int:
        if name not in self.names:
            raise KeyError(f"no state '{name}' in this measured set; states are {self.names}")
        return self.names.index(name)

    def state_markers(self, name: str) -> np.ndarray:
        return self.markers[self.index(name)]


def parse_photo_name(filename: str | os.PathLike) -> dict[str, Any]:
    """Trajectory, depth and angle from a flat-tip photo name.

    `twist_x_press_depth=2_angle=20_...jpg` -> twist_x, 2 mm, 20 deg; `press_press_depth=0_...` and
    `sensor_default_state.png` are rest states. The angle is kept only for twists (the file names of
    press and slide photos carry an unused default angle).
    """
    stem = Path(filename).name
    if stem.startswith("sensor_default_state"):
        return {"trajectory": "rest", "depth_mm": 0.0, "angle_deg": None}
    m = _NAME_RE.match(stem)
    if m is None:
        raise ValueError(f"{filename}: cannot parse the photo name; expected "
                         "'<press|twist_z|twist_x|slide>_press_depth=<mm>_angle=<deg>_...'")
    kind, depth = m["kind"], float(m["depth"])
    if kind == "press" and depth == 0:
        kind = "rest"  # touching without pressing: the background / displacement reference
    if kind.startswith("twist") and not m["angle"]:  # the twin would silently twist by SPEC's canonical angle
        raise ValueError(f"{filename}: a {kind} photo name needs its angle ('_angle=<deg>'); rename the photo or "
                         "list it in a photos_manifest with its angle")
    angle = float(m["angle"]) if kind.startswith("twist") else None
    return {"trajectory": kind, "depth_mm": depth, "angle_deg": angle}


def make_measured_set(markers: np.ndarray, found: np.ndarray, rest: np.ndarray,
                      states: list[MeasuredState], **meta: Any) -> MeasuredSet:
    """Build a set from ordered markers; the displacement is computed here (markers - rest)."""
    markers = np.asarray(markers, dtype=np.float32)
    rest = np.asarray(rest, dtype=np.float32)
    return MeasuredSet(markers=markers, displacement=(markers - rest[None]).astype(np.float32),
                       rest=rest, found=np.asarray(found, dtype=bool), states=list(states),
                       meta=dict(meta))


def _paths(path: str | os.PathLike) -> tuple[Path, Path]:
    stem = Path(path)
    if stem.suffix in {".npz", ".json"}:
        stem = stem.with_suffix("")
    return stem.with_name(stem.name + ".npz"), stem.with_name(stem.name + ".json")


def _check_arrays(arrays: dict[str, np.ndarray], where: Path) -> None:
    keys = sorted(arrays)
    if keys != sorted(NPZ_KEYS):
        raise ValueError(f"{where}: has keys {keys}, a measured set needs exactly {sorted(NPZ_KEYS)}; "
                         "re-save it with palpation.measured.save_measured_set")
    markers, disp, rest, found = (np.asarray(arrays[k]) for k in NPZ_KEYS)
    if markers.ndim != 3 or markers.shape[2] != 2:
        raise ValueError(f"{where}: markers has shape {markers.shape}, expected (S, {N_MARKERS}, 2)")
    if markers.shape[1] != N_MARKERS:
        raise ValueError(f"{where}: markers has {markers.shape[1]} markers per state, expected "
                         f"{N_MARKERS}; order detections onto the template (palpation.markers.order)")
    n = markers.shape[0]
    for key, arr, shape in (("displacement", disp, markers.shape), ("rest", rest, (N_MARKERS, 2)),
                            ("found", found, (n, N_MARKERS))):
        if arr.shape != shape:
            raise ValueError(f"{where}: {key} has shape {arr.shape}, expected {shape}")
    for key, arr in (("markers", markers), ("displacement", disp), ("rest", rest)):
        if not np.issubdtype(arr.dtype, np.floating):
            raise ValueError(f"{where}: {key} has dtype {arr.dtype}, expected float32 pixels")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{where}: {key} has NaN/inf coordinates; fill missing markers (and set "
                             "found=False for them) before saving")
    if found.dtype != bool:
        raise ValueError(f"{where}: found has dtype {found.dtype}, expected bool")
    err = np.abs(disp.astype(np.float64) - (markers.astype(np.float64) - rest[None])).max(initial=0.0)
    if err > DISPLACEMENT_TOL_PX:
        raise ValueError(f"{where}: displacement differs from markers - rest by up to {err:.3g} px; "
                         "recompute it as markers - rest")


def _check_meta(meta: dict[str, Any], n_states: int, where: Path) -> list[MeasuredState]:
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise ValueError(f"{where}: not a measured-set metadata file (format != '{FORMAT_NAME}'); "
                         "see docs/measured_format.md")
    if meta.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{where}: format_version {meta.get('format_version')!r} is not supported "
                         f"(this code reads {FORMAT_VERSION}); re-save with save_measured_set")
    raw = meta.get("states")
    if not isinstance(raw, list):
        raise ValueError(f"{where}: 'states' must be a list with one entry per state")
    if len(raw) != n_states:
        raise ValueError(f"{where}: lists {len(raw)} states but the npz holds {n_states}; "
                         "make both describe the same states in the same order")
    states = []
    for i, entry in enumerate(raw):
        if not isinstance(entry, dict) or not {"name", "source_file", "trajectory"} <= entry.keys():
            raise ValueError(f"{where}: state {i} needs 'name', 'source_file' and 'trajectory'")
        if entry["trajectory"] not in TRAJECTORIES:
            raise ValueError(f"{where}: state {i} ('{entry['name']}') has unknown trajectory "
                             f"'{entry['trajectory']}'; use one of {list(TRAJECTORIES)}")
        for key in ("depth_mm", "angle_deg"):
            value = entry.get(key)
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                      or not np.isfinite(value)):
                raise ValueError(f"{where}: state {i} ('{entry['name']}') has {key}={value!r}; "
                                 "use a finite number or null")
        states.append(MeasuredState(
            name=str(entry["name"]), source_file=str(entry["source_file"]),
            trajectory=entry["trajectory"],
            depth_mm=None if entry.get("depth_mm") is None else float(entry["depth_mm"]),
            angle_deg=None if entry.get("angle_deg") is None else float(entry["angle_deg"])))
    names = [s.name for s in states]
    if len(set(names)) != len(names):
        raise ValueError(f"{where}: state names must be unique, got {names}")
    return states


def _metadata(mset: MeasuredSet) -> dict[str, Any]:
    meta = {k: v for k, v in mset.meta.items() if k not in {"format", "format_version", "states"}}
    meta.setdefault("units", {"markers": "px", "displacement": "px", "depth_mm": "mm",
                              "angle_deg": "deg", "mm_per_px": 2.0 / 55.0})
    meta.setdefault("order", "base-graph order (SPEC 5.2): 0 = centre, then rings by bearing")
    return {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "n_markers": N_MARKERS,
            **meta, "states": [asdict(s) for s in mset.states]}


def save_measured_set(path: str | os.PathLike, mset: MeasuredSet) -> tuple[Path, Path]:
    """Validate, then write `<path>.npz` and `<path>.json` atomically; returns both paths."""
    npz_path, json_path = _paths(path)
    arrays = {"markers": mset.markers, "displacement": mset.displacement, "rest": mset.rest,
              "found": mset.found}
    _check_arrays(arrays, npz_path)
    meta = json.loads(json.dumps(_metadata(mset), default=str))  # plain JSON types, as on load
    _check_meta(meta, mset.markers.shape[0], json_path)
    save_npz(npz_path, **{k: (v.astype(bool) if k == "found" else np.asarray(v, np.float32))
                          for k, v in arrays.items()})
    save_json(json_path, meta)
    return npz_path, json_path


def load_measured_set(path: str | os.PathLike) -> MeasuredSet:
    """Read and validate a measured set (`path` with or without .npz/.json)."""
    npz_path, json_path = _paths(path)
    for p in (npz_path, json_path):
        if not p.exists():
            raise FileNotFoundError(f"{p}: missing; a measured set is a pair <name>.npz + <name>.json "
                                    "(see docs/measured_format.md)")
    arrays = read_npz(npz_path, fix="re-save it with palpation.measured.save_measured_set (or rerun its rule)")
    _check_arrays(arrays, npz_path)
    meta = read_json(json_path, "fix or re-save it with palpation.measured.save_measured_set", kind=dict)
    states = _check_meta(meta, arrays["markers"].shape[0], json_path)
    extra = {k: v for k, v in meta.items() if k not in {"format", "format_version", "states"}}
    return MeasuredSet(markers=arrays["markers"].astype(np.float32),
                       displacement=arrays["displacement"].astype(np.float32),
                       rest=arrays["rest"].astype(np.float32), found=arrays["found"].astype(bool),
                       states=states, meta=extra)
