"""Every checked reader fed a missing, an empty, a damaged and a wrong-typed file, and random bytes, truncations
and manifest rows: one line naming the file, what is wrong and the fix, never another exception type."""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path
from typing import Callable, NamedTuple

import cv2
import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from palpation import readers
from palpation.graph.layout import rest_layout
from palpation.markers.manifest import read_manifest
from palpation.mapping.photo import read_polygons
from palpation.model.checkpoint import load_checkpoint
from palpation.report.reproduction import run_start
from palpation.twin.mesh import SensorMesh, box_mesh
from palpation.twin.output import TrajectoryRecord, read_sim_manifest, write_outputs

FIX = "rerun rule make_it"


class Format(NamedTuple):
    """A good file, its reader, a damaged and a wrong-typed version, and the words of the reader's fix."""

    name: str
    file: str
    good: Callable[[Path], None]
    read: Callable[[Path], object]
    damage: Callable[[Path], None]
    wrong: Callable[[Path], None]
    fix: str


def half(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])


def text(content: str) -> Callable[[Path], None]:
    return lambda path: path.write_text(content)


def video(size=(32, 32)) -> Callable[[Path], None]:
    def write(path: Path) -> None:
        w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 5, size)
        for i in range(6):
            w.write(np.full((size[1], size[0], 3), 40 * i, np.uint8))
        w.release()
    return write


def read_video(path: Path) -> int:
    cap, n = readers.open_video(path, FIX, size=(32, 32))
    cap.release()
    return n


def checkpoint(path: Path, skip_width: int | None = None) -> None:
    from palpation.graph.normalise import NormStats
    from palpation.model.checkpoint import save_checkpoint
    from palpation.model.config import ModelConfig
    from palpation.model.stgnn import STGNN

    cfg = ModelConfig("compact", 8, 16, 4)
    stats = NormStats((0.0,), (1.0,), (0.0,), (1.0,), (0.0,), (1.0,), 0.9, 4, "sample")
    save_checkpoint(path, STGNN(3, cfg), cfg, stats, rest_layout("ideal"))
    if skip_width is not None:  # weights of one model under another's config
        payload = torch.load(path, weights_only=True)
        payload["model_config"]["skip_width"] = skip_width
        buf = io.BytesIO()
        torch.save(payload, buf)
        path.write_bytes(buf.getvalue())


def mesh_with_bad_tets(path: Path) -> None:
    m = box_mesh()
    m.tets = m.tets + m.n_nodes  # indices past the last node
    m.save(path)


def sim_record(name: str = "trajectory_0000", frames: int = 2) -> TrajectoryRecord:
    rest = rest_layout("ideal").astype(np.float32)
    return TrajectoryRecord(
        name=name, kind="press", seed=0, params={"E": 1.0}, markers=np.tile(rest, (frames, 1, 1)),
        labels=np.zeros((frames, 127), np.int8), centreline_px=np.zeros((frames, 50, 2), np.float32),
        contact=np.zeros(frames, bool), T_BA=np.tile(np.eye(4), (frames, 1, 1)),
        frame_index=np.arange(frames, dtype=np.int32), centreline_A=np.zeros((50, 3)), rest_markers_px=rest)


def sim_set(path: Path) -> None:
    write_outputs(path.parent, [sim_record()], [], manifest_name=path.name)


def sim_bad_row(path: Path) -> None:
    sim_set(path)
    data = json.loads(path.read_text())
    data["files"][0]["kind"] = "wiggle"
    path.write_text(json.dumps(data))


def photos_dir(path: Path) -> Path:
    folder = path.parent / "photos"
    folder.mkdir(exist_ok=True)
    for name in ("a.jpg", "b.jpg"):
        (folder / name).write_bytes(b"")
    return folder


def vgg(regions) -> Callable[[Path], None]:
    return text(json.dumps({"phantom.jpg": {"regions": regions}}))


POLYGON = [{"shape_attributes": {"name": "polygon", "all_points_x": [0, 9, 9], "all_points_y": [0, 0, 9]}}]

FORMATS = {f.name: f for f in [
    Format("npz", "a.npz", lambda p: np.savez(p, a=np.arange(400.0)),
           lambda p: readers.read_npz(p, ("a",), FIX, finite=("a",)), half,
           lambda p: np.savez(p, a=np.array(["x"])), FIX),
    Format("json", "a.json", text('{"x": 1}'), lambda p: readers.read_json(p, FIX, kind=dict, keys=("x",)),
           text('{"x": '), text("[1, 2]"), FIX),
    Format("yaml", "a.yaml", text("x: 1\n"), lambda p: readers.read_yaml(p, FIX), text("x: [1, 2\n"),
           text("- 1\n- 2\n"), FIX),
    Format("csv", "a.csv", text("a,b\n1,2\n"), lambda p: readers.read_csv(p, ("a", "b"), FIX),
           lambda p: p.write_bytes(b"\xff\xfe\x00a,\x00\x81\n"), text("a,c\n1,2\n"), FIX),
    Format("text", "a.txt", text("123.5\n"), lambda p: readers.read_text(p, FIX),
           lambda p: p.write_bytes(b"12\xff\xfe3"), text("yesterday\n"), FIX),
    Format("image", "a.png", lambda p: cv2.imwrite(str(p), np.arange(4096, dtype=np.uint8).reshape(64, 64)),
           lambda p: readers.read_image(p, FIX), half, text('{"not": "an image"}'), FIX),
    Format("video", "a.mp4", video(), read_video, half, video((16, 16)), FIX),
    Format("checkpoint", "checkpoint.pt", checkpoint, load_checkpoint, half,
           lambda p: checkpoint(p, skip_width=8), "rerun its train rule"),
    Format("mesh", "mesh.npz", lambda p: box_mesh().save(p), SensorMesh.load, half, mesh_with_bad_tets,
           "snakemake results/twin/mesh_<resolution>.npz"),
    Format("sim_manifest", "manifest.json", sim_set, read_sim_manifest, half, sim_bad_row,
           "rerun the simulate_dataset rule"),
    Format("photo_manifest", "manifest.csv", text("file,kind,depth,angle\na.jpg,press,2,\nb.jpg,twist_x,2,20\n"),
           lambda p: read_manifest(p, photos_dir(p)), lambda p: p.write_bytes(b"file,kind\n\xff\xfe\x00\x81\n"),
           text("file,kind,depth,angle\na.jpg,press,2,\nb.jpg,twist_x,2,\n"), "docs/measured_format.md"),
    Format("vgg_labels", "labels.json", vgg(POLYGON), read_polygons, half, vgg([{"shape": 1}]),
           "phantom-labels-vgg.json"),
]}
# what the wrong-typed file of each format is refused for
WRONG = {"npz": "expected numbers", "json": "expected a mapping", "yaml": "expected a mapping",
         "csv": "missing column(s) ['b']", "text": "'yesterday'", "image": "cannot be decoded",
         "video": "frame size (16, 16)", "checkpoint": "does not fit its model", "mesh": "`tets` indexes nodes",
         "sim_manifest": "kind 'wiggle'", "photo_manifest": "row 2 column 'angle' is empty",
         "vgg_labels": "not the VGG annotator format"}


def place(fmt: Format, tmp_path: Path) -> Path:
    folder = tmp_path / fmt.name
    folder.mkdir(exist_ok=True)
    return folder / fmt.file


@pytest.mark.parametrize("name", FORMATS)
def test_good_file_reads(name, tmp_path):  # each fault below is the only difference from a good file
    fmt = FORMATS[name]
    path = place(fmt, tmp_path)
    fmt.good(path)
    assert fmt.read(path) is not None


@pytest.mark.parametrize("name", FORMATS)
def test_missing_file(name, tmp_path, fault):
    """a file a reader needs is not there"""
    fmt = FORMATS[name]
    path = place(fmt, tmp_path)
    photos_dir(path)
    with fault(FileNotFoundError, str(path), fmt.fix):
        fmt.read(path)


@pytest.mark.parametrize("name", FORMATS)
def test_empty_file(name, tmp_path, fault):
    """a file of 0 bytes (a writer killed before its first byte, a failed copy)"""
    fmt = FORMATS[name]
    path = place(fmt, tmp_path)
    path.write_bytes(b"")
    with fault(ValueError, str(path), fmt.fix):
        fmt.read(path)


@pytest.mark.parametrize("name", FORMATS)
def test_damaged_file(name, tmp_path, fault):
    """a file cut short or holding bytes its parser rejects"""
    fmt = FORMATS[name]
    path = place(fmt, tmp_path)
    fmt.good(path)
    fmt.damage(path)
    with fault(ValueError, str(path), fmt.fix):
        fmt.read(path)


@pytest.mark.parametrize("name", FORMATS)
def test_wrong_typed_file(name, tmp_path, fault):
    """a whole file of the wrong type, shape, keys or columns"""
    fmt = FORMATS[name]
    path, read = place(fmt, tmp_path), fmt.read
    if name == "text":  # text that must hold a number: the run-start stamp under a results root
        path = tmp_path / "bench" / ".run_start"
        path.parent.mkdir()
        read = lambda p: run_start(p.parent.parent)  # noqa: E731
    fmt.wrong(path)
    with fault(ValueError, str(path), WRONG[name], "; "):
        read(path)


def test_npz_nan_where_numbers_must_be_finite(tmp_path, fault):
    """a NaN in an array that must be finite (a mesh node)"""
    m = box_mesh()
    m.nodes[3, 1] = np.nan
    path = tmp_path / "mesh.npz"
    m.save(path)
    with fault(ValueError, str(path), "`nodes` holds 1 NaN/inf", "snakemake"):
        SensorMesh.load(path)


def test_npz_wrong_shape(tmp_path, fault):
    """mesh nodes of shape (N, 2) instead of (N, 3)"""
    m = box_mesh()
    m.nodes = m.nodes[:, :2]
    path = tmp_path / "mesh.npz"
    m.save(path)
    with fault(ValueError, str(path), "`nodes` has shape (27, 2), expected (N, 3)", "snakemake"):
        SensorMesh.load(path)


def test_bare_npy_for_an_npz(tmp_path, fault):
    """a .npy array saved where an npz archive belongs"""
    path = tmp_path / "scores.npz"
    with path.open("wb") as f:
        np.save(f, np.zeros(3))
    with fault(ValueError, str(path), "not a readable npz archive", FIX):
        readers.read_npz(path, fix=FIX)


def test_folder_instead_of_a_file(tmp_path, fault):
    """a folder where a file is expected"""
    with fault(FileNotFoundError, str(tmp_path), "is a folder", FIX):
        readers.read_json(tmp_path, FIX)


def test_sim_manifest_row_without_a_file(tmp_path, fault):
    """a Sim manifest row naming no file"""
    path = tmp_path / "manifest.json"
    path.write_text(json.dumps({"files": [{"kind": "press"}]}))
    with fault(ValueError, str(path), "files row 1", "names no trajectory file", "simulate_dataset"):
        read_sim_manifest(path)


def test_study_file_damaged(tmp_path, fault):
    """an Optuna journal (the loop's resumable study) holding garbage"""
    import optuna

    from palpation.calibration.search import open_study

    path = tmp_path / "study.journal"
    path.write_text("{not json\n")
    with fault(ValueError, str(path), "is damaged", "delete it"):
        open_study(path, "s", optuna.samplers.RandomSampler(0), "minimize")


# ---- properties: random input either parses or raises the one-line error, nothing else ----

def one_line_error(exc: BaseException, path: Path) -> None:
    assert isinstance(exc, (ValueError, FileNotFoundError)), f"{type(exc).__name__}: {exc}"
    msg = str(exc)
    assert "\n" not in msg.strip() and "Traceback" not in msg, msg
    assert str(path) in msg and "; " in msg, msg


def read_or_refuse(fmt: Format, path: Path) -> None:
    try:
        fmt.read(path)
    except Exception as exc:  # noqa: BLE001  the property: only the checked errors come out
        one_line_error(exc, path)


# a garbage "checkpoint" makes torch warn about its pickle protocol before it refuses the file
NOISE = pytest.mark.filterwarnings("ignore:Detected pickle protocol")
# PALPATION_FORMAT_EXAMPLES=1500 for a long hunt; 30 keeps each property case near 0.1 s
PROPERTY = settings(max_examples=int(os.environ.get("PALPATION_FORMAT_EXAMPLES", 30)), deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])  # tmp_path: rewritten each example


@NOISE
@pytest.mark.parametrize("name", FORMATS)
@PROPERTY
@given(data=st.binary(max_size=400))
def test_random_bytes(name, data, tmp_path):
    fmt = FORMATS[name]
    path = place(fmt, tmp_path)
    photos_dir(path)
    path.write_bytes(data)
    read_or_refuse(fmt, path)


@pytest.fixture(scope="module")
def good_bytes(tmp_path_factory):
    root = tmp_path_factory.mktemp("good")
    out = {}
    for fmt in FORMATS.values():
        path = place(fmt, root)
        fmt.good(path)
        out[fmt.name] = path.read_bytes()
    return out


@NOISE
@pytest.mark.parametrize("name", FORMATS)
@PROPERTY
@given(cut=st.floats(0, 1), flip=st.integers(0, 2**16))
def test_random_truncation_or_flipped_byte(name, cut, flip, tmp_path, good_bytes):
    fmt = FORMATS[name]
    path = place(fmt, tmp_path)
    photos_dir(path)
    data = bytearray(good_bytes[name][: int(cut * len(good_bytes[name]))])
    if data and flip % 2:  # half the cases also flip one byte of what is left
        data[flip % len(data)] ^= 0xFF
    path.write_bytes(bytes(data))
    read_or_refuse(fmt, path)


CELL = st.one_of(st.none(), st.text(max_size=6), st.floats(allow_nan=True, allow_infinity=True),
                 st.integers(-5, 400), st.booleans())
FILE = st.one_of(st.sampled_from(["a.jpg", "b.jpg", "c.jpg", "../a.jpg"]), st.text(max_size=6))
ROW = st.fixed_dictionaries({"file": FILE,
                             "kind": st.one_of(st.sampled_from(["rest", "press", "twist_z", "twist_x", "slide"]),
                                               st.text(max_size=8)),
                             "depth": CELL, "angle": CELL})


@PROPERTY
@given(rows=st.lists(ROW, max_size=4), as_yaml=st.booleans())
def test_random_photo_manifest_rows(rows, as_yaml, tmp_path):
    import yaml

    path = tmp_path / ("manifest.yaml" if as_yaml else "manifest.csv")
    if as_yaml:
        path.write_text(yaml.safe_dump({"photos": rows}))
    else:
        buf = io.StringIO()
        writer = csv.DictWriter(buf, ["file", "kind", "depth", "angle"], lineterminator="\n")
        writer.writeheader()
        writer.writerows({k: "" if v is None else v for k, v in r.items()} for r in rows)
        path.write_text(buf.getvalue())
    try:
        photos = read_manifest(path, photos_dir(path))
    except Exception as exc:  # noqa: BLE001
        one_line_error(exc, path)
        return
    assert photos and all(p.angle_deg is not None for p in photos if p.trajectory.startswith("twist"))
    assert all(np.isfinite(p.depth_mm) and p.depth_mm >= 0 for p in photos)


JSON = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(), st.text(max_size=8)),
                    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=5), inner,
                                                                                         max_size=3)), max_leaves=8)
SIM_ROW = st.one_of(st.sampled_from(["trajectory_0000.npz", "gone.npz", ""]), JSON,
                    st.fixed_dictionaries({"file": st.one_of(st.just("trajectory_0000.npz"), JSON)},
                                          optional={"kind": st.one_of(st.just("press"), JSON), "params": JSON}))


@PROPERTY
@given(rows=st.one_of(st.lists(SIM_ROW, max_size=3), JSON), key=st.sampled_from(["files", "trajectories", None]))
def test_random_sim_manifest_rows(rows, key, tmp_path):
    path = tmp_path / "sim" / "manifest.json"
    path.parent.mkdir(exist_ok=True)
    np.savez(path.parent / "trajectory_0000.npz", markers=np.zeros((1, 127, 2)))
    path.write_text(json.dumps(rows if key is None else {key: rows}))
    try:
        _, files = read_sim_manifest(path)
    except Exception as exc:  # noqa: BLE001
        one_line_error(exc, path)
        return
    assert files and all(f.is_file() for f in files)
