"""A photo manifest: which state each photo of a folder shows, for photos not named like the paper's.

A CSV or YAML file with one row per photo and the columns `file` (relative to the photo folder),
`kind` (rest, press, twist_z, twist_x, slide), `depth` (mm) and `angle` (deg, twists only; may be
empty). See docs/measured_format.md. The paper's `<kind>_press_depth=<mm>_angle=<deg>_...` names need
no manifest (`paper_names`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from palpation.measured import TRAJECTORIES, parse_photo_name
from palpation.readers import read_csv, read_yaml

COLUMNS = ("file", "kind", "depth", "angle")


@dataclass(frozen=True)
class PhotoInfo:
    """One photo and the state it shows."""

    path: Path
    name: str  # short state name, e.g. press_d4, twist_x_d2_a20
    trajectory: str
    depth_mm: float
    angle_deg: float | None


def state_label(kind: str, depth_mm: float, angle_deg: float | None) -> str:
    return f"{kind}_d{depth_mm:g}" + (f"_a{angle_deg:g}" if angle_deg is not None else "")


def state_name(path: str | os.PathLike) -> str:
    """Short state name from a paper-style photo name: press_d4, twist_x_d2_a20, sensor_default_state, ...

    The kind is the name's prefix, so a press at 0 mm stays `press_d0` although its trajectory is rest.
    """
    stem = Path(path).name
    if stem.startswith("sensor_default_state"):
        return "sensor_default_state"
    info = parse_photo_name(stem)
    return state_label(stem.split("_press_depth=")[0], info["depth_mm"], info["angle_deg"])


def _rows(path: Path) -> list[dict]:
    """Raw rows of a .csv or .yaml/.yml manifest (a list of mappings, or {photos: [...]})."""
    fix = f"write a CSV/YAML table with columns {', '.join(COLUMNS)} (docs/measured_format.md)"
    suffix = path.suffix.lower()
    if suffix == ".csv":
        frame = read_csv(path, fix=fix, what="photo manifest", rows=False, dtype=str, keep_default_na=False,
                         skipinitialspace=True)
        return frame.to_dict("records")
    if suffix in {".yaml", ".yml"}:
        data = read_yaml(path, fix, "photo manifest", kind=(dict, list))
        data = data.get("photos") if isinstance(data, dict) else data
        if not isinstance(data, list) or not all(isinstance(r, dict) for r in data):
            raise ValueError(f"photo manifest {path}: expected a list of rows (mappings), or 'photos:' holding one; "
                             f"{fix}")
        return data
    raise ValueError(f"photo manifest {path}: unknown format '{suffix}'; use .csv, .yaml or .yml")


def _number(value, path: Path, row: int, column: str, allow_empty: bool) -> float | None:
    text = "" if value is None else str(value).strip()
    if text == "" and allow_empty:
        return None
    try:
        number = float(text)
    except ValueError:
        number = math.nan
    if not math.isfinite(number) or (column == "depth" and number < 0):
        need = "a depth in mm >= 0" if column == "depth" else "an angle in degrees, or empty"
        raise ValueError(f"photo manifest {path}: row {row} column '{column}' is {text!r}; write {need}")
    return number


def read_manifest(path: str | os.PathLike, photos_dir: str | os.PathLike) -> list[PhotoInfo]:
    """The photos a manifest lists, in its order; a bad row raises a one-line error naming the column."""
    path, photos_dir = Path(path), Path(photos_dir)
    if not path.is_file():
        raise FileNotFoundError(f"photo manifest {path} does not exist; set photos_manifest to a CSV/YAML "
                                f"file with columns {', '.join(COLUMNS)} (docs/measured_format.md)")
    rows = _rows(path)
    if not rows:
        raise ValueError(f"photo manifest {path}: no rows; list one photo per row ({', '.join(COLUMNS)})")
    photos, names = [], set()
    for row_no, row in enumerate(rows, start=1):
        row = {str(k).strip().lower(): v for k, v in row.items()}
        missing = [c for c in COLUMNS if c not in row]
        if missing:
            raise ValueError(f"photo manifest {path}: column '{missing[0]}' missing (row {row_no}); a manifest "
                             f"needs columns {', '.join(COLUMNS)}")
        file = str(row["file"] or "").strip()
        if not file or not (photos_dir / file).is_file():
            raise FileNotFoundError(f"photo manifest {path}: row {row_no} column 'file': "
                                    f"{str(photos_dir / file)!r} does not exist; paths are relative to photos_dir")
        kind = str(row["kind"] or "").strip()
        if kind not in TRAJECTORIES:
            raise ValueError(f"photo manifest {path}: row {row_no} column 'kind' is {kind!r}; use one of "
                             f"{', '.join(TRAJECTORIES)}")
        depth = _number(row["depth"], path, row_no, "depth", allow_empty=False)
        angle = _number(row["angle"], path, row_no, "angle", allow_empty=True)
        if kind.startswith("twist") and angle is None:  # the twin would silently twist by SPEC's canonical angle
            raise ValueError(f"photo manifest {path}: row {row_no} column 'angle' is empty, but a {kind} row needs "
                             "its twist angle; write the angle in degrees")
        angle = angle if kind.startswith("twist") else None  # as for the paper's names
        name = state_label(kind, depth, angle)
        if name in names:  # two photos of one state: keep both, told apart by the file stem
            name = f"{name}_{Path(file).stem}"
        if name in names:
            raise ValueError(f"photo manifest {path}: row {row_no} column 'file' lists {file!r} twice; "
                             "list each photo once")
        names.add(name)
        photos.append(PhotoInfo(photos_dir / file, name, kind, depth, angle))
    return photos


def paper_names(photos: list[Path]) -> list[PhotoInfo]:
    """PhotoInfo from the paper's file names (`parse_photo_name`)."""
    out = []
    for p in photos:
        info = parse_photo_name(p.name)
        out.append(PhotoInfo(p, state_name(p), info["trajectory"], info["depth_mm"], info["angle_deg"]))
    return out
