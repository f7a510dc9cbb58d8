"""Synthetic inputs in the formats the vessel-map stage reads: a straight vessel, known poses, scores."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from palpation.camera import DEFAULT_CAMERA
from palpation.graph.augment import sim_labels
from palpation.mapping.lift import PLANE_MM, sim_to_world
from palpation.markers.lattice import ideal_hex_lattice

VESSEL_Y_MM = 39.0  # the twin's vessel axis: along x at y = 39 mm (docs/sim_format.md)
REST_PX = ideal_hex_lattice(55.0, 0.0, (1040.0, 584.0))


def dome_down(tip_mm) -> np.ndarray:
    """T_BA (metres) of a sensor facing down (R_y(180 deg)) with its tip at `tip_mm`."""
    T = np.eye(4)
    T[:3, :3] = np.diag([-1.0, 1.0, -1.0])
    T[:3, 3] = np.asarray(tip_mm, float) / 1000.0
    return T


def centreline_px(T_BA_m: np.ndarray) -> np.ndarray:
    """The vessel axis (x 19..59 mm, y 39 mm, in the plane the markers are lifted to) through each camera."""
    axis_A = np.stack([np.linspace(19, 59, 50), np.full(50, VESSEL_Y_MM), np.full(50, 15.0)], 1) / 1000.0
    R, t = T_BA_m[:, :3, :3], T_BA_m[:, :3, 3]
    p_B = np.einsum("fji,fpj->fpi", R, axis_A[None] - t[:, None]) * 1000.0  # R^T (p_A - t), mm
    return DEFAULT_CAMERA.project(p_B + [0.0, 0.0, 19.0]).astype(np.float32)


def write_sim_set(folder: Path, n_files: int = 20, n_frames: int = 144, step_mm: float = 0.25) -> Path:
    """Trajectories sliding along +y across the vessel: markers fixed on the lattice (the lifted grid
    slides with the pose), labels by the SPEC 30 px rule from the projected axis. Returns the manifest."""
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for i in range(n_files):
        x0 = 39.0 + (i % 3)  # slides a little apart so the maps differ
        y = VESSEL_Y_MM - 0.5 * step_mm * n_frames + step_mm * np.arange(n_frames)
        T = np.stack([dome_down((x0, yy, 12.0)) for yy in y])
        markers = np.broadcast_to(REST_PX, (n_frames, 127, 2)).astype(np.float32)
        line, contact = centreline_px(T), np.ones(n_frames, bool)
        name = f"trajectory_{i:04d}.npz"
        np.savez(folder / name, markers=markers, labels=sim_labels(markers, line, contact), T_BA=T,
                 centreline_px=line, contact=contact)
        entries.append({"file": name})
    (folder / "manifest.json").write_text(json.dumps({"format": "palpation-sim/1", "files": entries}))
    return folder / "manifest.json"


def sim_scores(manifest: Path, shift_mm: float = 0.0, clip_len: int = 5, stride: int = 24, seed: int = 0,
               split_start: int | None = None) -> dict:
    """Test-split scores with their ids: high probability for markers within 1 mm of the vessel moved by
    `shift_mm`."""
    from palpation.graph.clips import ClipSet
    from palpation.graph.sources import load_sim, sim_trajectory_files, split_sorted

    files = {f.stem: f for f in sim_trajectory_files(manifest)}
    ids = split_sorted(list(files), "test")
    data = [np.load(files[i]) for i in ids]
    seq, frame = ClipSet(load_sim(manifest, "test", stride), clip_len, REST_PX).central_frames()
    rng = np.random.default_rng(seed)
    probs, labels = [], []
    for s, f in zip(seq, frame):
        d = data[s]
        world = sim_to_world(DEFAULT_CAMERA.unproject_to_plane(d["markers"][f], PLANE_MM["sim"])[None],
                             d["T_BA"][f][None])[0]
        near = np.abs(world[:, 1] - VESSEL_Y_MM - shift_mm) < 1.0
        probs.append(np.where(near, 0.8 + rng.uniform(-0.1, 0.1, 127), 0.2 + rng.uniform(-0.05, 0.05, 127)))
        labels.append(d["labels"][f])
    return {"probs": np.concatenate(probs).astype(np.float32), "labels": np.concatenate(labels).astype(np.int8),
            "sequence": seq, "frame": frame}


@pytest.fixture
def sim_set(tmp_path):
    return write_sim_set(tmp_path / "sim")


@pytest.fixture
def make_scores():
    """The `sim_scores` builder, for tests (conftest helpers are not importable in importlib mode)."""
    return sim_scores


@pytest.fixture
def make_sim_set():
    return write_sim_set
