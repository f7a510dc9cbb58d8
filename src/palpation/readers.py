"""Checked readers, one per file format: every file an app reads goes through one of them.

A missing file raises FileNotFoundError; an empty, truncated, damaged or wrong-typed one (missing keys or
columns, wrong dtype or shape, NaN where numbers must be finite, the wrong top-level type) raises ValueError.
Either way the message is one line naming the file, what is wrong and `fix` (how to get a good file back),
which `config_check.app_main` prints as the app's error (docs/DEVELOPING.md, "Errors"). Parser libraries
raise many exception types (zipfile, zlib, pickle, yaml, pandas, OpenCV, torch), so each reader catches
every exception around the parse call alone; what it checks after that raises its own messages.
Formats with more structure have their reader beside their writer and build on these: meshes
(twin.mesh.SensorMesh.load), Sim manifests (twin.output.read_sim_manifest), checkpoints
(model.checkpoint.load_checkpoint), photo manifests (markers.manifest.read_manifest), measured sets.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

DEFAULT_FIX = "rerun the rule that writes it"
_ABSENT = object()
_TYPES = {dict: "a mapping", list: "a list"}


def _name(path: Path, what: str) -> str:
    return f"{what} {path}" if what else str(path)


def one_line(exc: BaseException) -> str:
    """An exception as one short line (its type and text, lines joined, cut at 200 characters): parsers' errors
    can span lines (torch's load_state_dict, sqlalchemy, pandas)."""
    text = " ".join(line.strip() for line in str(exc).strip().splitlines())
    return f"{type(exc).__name__}: {text[:200]}" if text else type(exc).__name__


def existing(path: str | os.PathLike, fix: str = DEFAULT_FIX, what: str = "", empty_ok: bool = False) -> Path:
    """`path` as a Path, after FileNotFoundError (absent, or a folder) or ValueError (0 bytes)."""
    path = Path(path)
    if not path.is_file():
        state = "is a folder, not a file" if path.is_dir() else "not found"
        raise FileNotFoundError(f"{_name(path, what)} {state}; {fix}")
    if not empty_ok and path.stat().st_size == 0:
        raise ValueError(f"{_name(path, what)} is empty (0 bytes); {fix}")
    return path


def _check_type(data: Any, kind: type | tuple[type, ...] | None, path: Path, what: str, fix: str) -> None:
    if kind is not None and not isinstance(data, kind):
        want = " or ".join(_TYPES.get(k, k.__name__) for k in (kind if isinstance(kind, tuple) else (kind,)))
        raise ValueError(f"{_name(path, what)}: expected {want} at the top level, got {type(data).__name__}; {fix}")


def _check_keys(data: Any, keys: tuple[str, ...], path: Path, what: str, fix: str) -> None:
    missing = [k for k in keys if k not in data]
    if missing:
        raise ValueError(f"{_name(path, what)} lacks the key(s) {missing}; {fix}")


def read_text(path: str | os.PathLike, fix: str = DEFAULT_FIX, what: str = "", empty_ok: bool = False) -> str:
    """A UTF-8 text file's content."""
    data = existing(path, fix, what, empty_ok).read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{_name(path, what)} is not readable UTF-8 text ({one_line(exc)}); {fix}") from None


def read_npz(path: str | os.PathLike, keys: tuple[str, ...] = (), fix: str = DEFAULT_FIX, what: str = "", *,
             finite: tuple[str, ...] = (), shapes: dict[str, tuple] | None = None,
             dtypes: dict[str, str] | None = None) -> dict[str, np.ndarray]:
    """Every array of an npz archive, checked: `keys` present, the `finite` arrays numeric without NaN/inf,
    `shapes` matched (None: any length), `dtypes` of the given numpy kinds ("f" float, "iu" integer, "b" bool,
    "U" text). Object arrays are never unpickled."""
    path = existing(path, fix, what)
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as exc:  # noqa: BLE001  zipfile, zlib, EOFError, a bare .npy (no context manager)...
        raise ValueError(f"{_name(path, what)} is not a readable npz archive ({one_line(exc)}); {fix}") from None
    _check_keys(arrays, keys, path, what, fix)
    for key, kinds in (dtypes or {}).items():
        if key in arrays and arrays[key].dtype.kind not in kinds:
            raise ValueError(f"{_name(path, what)}: `{key}` has dtype {arrays[key].dtype}, expected kind "
                             f"{kinds!r}; {fix}")
    for key, shape in (shapes or {}).items():
        got = arrays[key].shape if key in arrays else None
        if got is not None and (len(got) != len(shape) or any(s is not None and s != g for s, g in zip(shape, got))):
            want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{_name(path, what)}: `{key}` has shape {got}, expected {want}; {fix}")
    for key in finite:
        if arrays[key].dtype.kind not in "fiub":
            raise ValueError(f"{_name(path, what)}: `{key}` has dtype {arrays[key].dtype}, expected numbers; {fix}")
        bad = np.size(arrays[key]) - np.count_nonzero(np.isfinite(arrays[key]))
        if bad:
            raise ValueError(f"{_name(path, what)}: `{key}` holds {bad} NaN/inf values; {fix}")
    return arrays


def read_json(path: str | os.PathLike, fix: str = DEFAULT_FIX, what: str = "", kind: type | tuple | None = None,
              keys: tuple[str, ...] = (), optional: bool = False) -> Any:
    """A JSON file's content, of type `kind` (dict, list) with the top-level `keys`; None for an absent
    `optional` file. NaN/Infinity literals are accepted (older files); save_json writes null."""
    if optional and not Path(path).exists():
        return None
    raw = existing(path, fix, what).read_bytes()
    try:
        data = json.loads(raw)
    except Exception as exc:  # noqa: BLE001  JSONDecodeError, UnicodeDecodeError, RecursionError (deep nesting)
        raise ValueError(f"{_name(path, what)} is not valid JSON ({one_line(exc)}); {fix}") from None
    _check_type(data, kind, path, what, fix)
    if keys:
        _check_type(data, dict, path, what, fix)
        _check_keys(data, keys, path, what, fix)
    return data


def read_yaml(path: str | os.PathLike, fix: str = DEFAULT_FIX, what: str = "", kind: type | tuple | None = dict,
              default: Any = _ABSENT) -> Any:
    """A YAML file's content (safe_load), of type `kind`; an empty document gives `default` when one is given."""
    import yaml

    raw = existing(path, fix, what, empty_ok=default is not _ABSENT).read_bytes()
    try:
        data = yaml.safe_load(raw)
    except Exception as exc:  # noqa: BLE001  yaml.YAMLError, UnicodeDecodeError, RecursionError
        raise ValueError(f"{_name(path, what)}: cannot parse it as YAML ({one_line(exc)}); {fix}") from None
    if data is None and default is not _ABSENT:
        return default
    _check_type(data, kind, path, what, fix)
    return data


def read_csv(path: str | os.PathLike, columns: tuple[str, ...] = (), fix: str = DEFAULT_FIX, what: str = "",
             rows: bool = True, **pandas_kw):
    """A CSV (or, with sep="\\t", TSV) table as a DataFrame with `columns`, and at least one row if `rows`."""
    import pandas as pd

    path = existing(path, fix, what)
    try:
        df = pd.read_csv(path, **pandas_kw)
    except Exception as exc:  # noqa: BLE001  EmptyDataError, ParserError, UnicodeDecodeError...
        raise ValueError(f"{_name(path, what)}: cannot parse it as CSV ({one_line(exc)}); {fix}") from None
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise ValueError(f"{_name(path, what)}: missing column(s) {missing} (it has {list(df.columns)[:12]}); {fix}")
    if rows and df.empty:
        raise ValueError(f"{_name(path, what)}: has a header but no rows; {fix}")
    return df


def _truncated_image(data: bytes) -> bool:
    """JPEG and PNG files end with a marker; OpenCV decodes a cut-short JPEG into a grey-filled image."""
    if data[:2] == b"\xff\xd8":
        return b"\xff\xd9" not in data[-4096:]
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return b"IEND" not in data[-64:]
    return False


def read_image(path: str | os.PathLike, fix: str = "restore it or remove it from the photo folder",
               what: str = "image", gray: bool = True) -> np.ndarray:
    """An image as (H, W) uint8 grayscale or (H, W, 3) uint8 BGR."""
    import cv2

    path = existing(path, fix, what)
    data = path.read_bytes()
    image = None
    if not _truncated_image(data):
        try:
            image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_COLOR)
        except cv2.error:
            image = None
    if image is None or image.size == 0:
        raise ValueError(f"{_name(path, what)} cannot be decoded: truncated, damaged or not an image file; {fix}")
    return image


def open_video(path: str | os.PathLike, fix: str = DEFAULT_FIX, what: str = "video",
               size: tuple[int, int] | None = None):
    """(an opened cv2.VideoCapture, its frame count); `size` (width, height) if given. The caller releases it."""
    import cv2

    path = existing(path, fix, what)
    cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)  # not OpenCV's image-sequence fallback for a still image
    n_frames = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
    got = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
    if n_frames <= 0:
        cap.release()
        raise ValueError(f"{_name(path, what)} cannot be decoded by OpenCV (not a video, or damaged); {fix}")
    if size is not None and got != tuple(size):
        cap.release()
        raise ValueError(f"{_name(path, what)}: frame size {got} is not the expected {tuple(size)}; {fix}")
    return cap, n_frames


def read_torch(path: str | os.PathLike, fix: str = DEFAULT_FIX, what: str = "", device: str = "cpu") -> Any:
    """A torch.save file, unpickled with weights_only (tensors and plain containers: no code runs)."""
    import torch

    path = existing(path, fix, what)
    try:
        return torch.load(path, map_location=device, weights_only=True)
    except Exception as exc:  # noqa: BLE001  RuntimeError, EOFError, UnpicklingError... for a damaged file
        raise ValueError(f"{_name(path, what)} is damaged or truncated ({one_line(exc)}); {fix}") from None
