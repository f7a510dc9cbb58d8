"""Stale or broken Sim data is never trained on: the manifest is the only list of files."""

import json

import numpy as np
import pytest

from palpation.graph.layout import rest_layout
from palpation.graph.sources import load_sim
from palpation.graph.synthetic import write_sim
from palpation.twin.output import FailedRecord, TrajectoryRecord, load_trajectory, write_outputs

REST = rest_layout("ideal")


@pytest.fixture
def sim(tmp_path):
    return write_sim(tmp_path / "sim", REST, n_traj=4, n_frames=30)


def record(name: str, frames: int = 3) -> TrajectoryRecord:
    return TrajectoryRecord(
        name=name, kind="slide", seed=0, params={"E": 1.0}, markers=np.zeros((frames, 127, 2), np.float32),
        labels=np.zeros((frames, 127), np.int8), centreline_px=np.zeros((frames, 50, 2), np.float32),
        contact=np.zeros(frames, bool), T_BA=np.tile(np.eye(4), (frames, 1, 1)),
        frame_index=np.arange(frames, dtype=np.int32), centreline_A=np.zeros((50, 3)),
        rest_markers_px=REST.astype(np.float32))


def failed(name: str) -> FailedRecord:
    return FailedRecord(name=name, kind="slide", seed=0, params={"E": 1.0}, detected_at_frame=20)


def test_empty_manifest_beside_stale_trajectories(sim, fault):
    """a rerun whose trajectories all diverged: manifest `files: []`, old npz still in the folder"""
    sim.write_text(json.dumps({"files": [], "failed": [{"name": "trajectory_0000"}]}))
    with fault(ValueError, str(sim), "lists no trajectory files", "rerun the simulate_dataset rule"):
        load_sim(sim, "all")


def test_unlisted_npz_in_the_folder_is_not_read(sim):
    """a stale trajectory file that the manifest does not list is ignored"""
    names = json.loads(sim.read_text())["trajectories"]
    sim.write_text(json.dumps({"trajectories": names[:2]}))  # the other two are a previous run's
    assert load_sim(sim, "all").ids == ["trajectory_0000", "trajectory_0001"]


def test_listed_trajectory_missing(sim, fault):
    """the manifest names a file that is gone"""
    (sim.parent / "trajectory_0002.npz").unlink()
    with fault(FileNotFoundError, "trajectory_0002.npz", str(sim), "rerun the simulate_dataset rule"):
        load_sim(sim, "all")


def test_manifest_not_json(sim, fault):
    """a truncated Sim manifest"""
    sim.write_text(sim.read_text()[:25])
    with fault(ValueError, str(sim), "not valid JSON", "rerun the simulate_dataset rule"):
        load_sim(sim, "train")


def test_manifest_missing(tmp_path, fault):
    """no Sim manifest at all"""
    with fault(FileNotFoundError, "manifest.json", "simulate_dataset rule"):
        load_sim(tmp_path / "manifest.json", "train")


def test_trajectory_truncated(sim, fault):
    """a truncated trajectory npz"""
    path = sim.parent / "trajectory_0001.npz"
    path.write_bytes(path.read_bytes()[:200])
    with fault(ValueError, str(path), "not a readable npz", "rerun the simulate_dataset rule"):
        load_sim(sim, "all")


def test_trajectory_with_nan_markers(sim, fault):
    """a NaN marker in a Sim clip"""
    path = sim.parent / "trajectory_0003.npz"
    with np.load(path) as z:
        arrays = dict(z)
    arrays["markers"][5, 7, 0] = np.nan
    np.savez(path, **arrays)
    with fault(ValueError, str(path), "`markers` holds 1 NaN/inf", "rerun the simulate_dataset rule"):
        load_sim(sim, "all")


def test_rerun_clears_previous_trajectories(tmp_path):
    """a rerun with fewer trajectories removes the previous run's files, keeps foreign files"""
    write_outputs(tmp_path, [record("trajectory_0000"), record("trajectory_0001")], [])
    np.savez(tmp_path / "notes.npz", x=np.zeros(2))  # not a trajectory: not ours to delete
    manifest = write_outputs(tmp_path, [record("trajectory_0000")], [failed("trajectory_0001")])
    assert sorted(p.name for p in tmp_path.glob("*.npz")) == ["notes.npz", "trajectory_0000.npz"]
    assert [f["file"] for f in json.loads(manifest.read_text())["files"]] == ["trajectory_0000.npz"]


def test_rerun_after_snakemake_removed_the_manifest(tmp_path):
    """Snakemake deletes the declared manifest before a rerun; the old trajectories still go"""
    write_outputs(tmp_path, [record("trajectory_0000"), record("trajectory_0001")], [])
    (tmp_path / "manifest.json").unlink()
    write_outputs(tmp_path, [], [failed("trajectory_0000"), failed("trajectory_0001")])
    assert list(tmp_path.glob("*.npz")) == []


def test_trajectory_file_of_another_format(tmp_path, fault):
    """a trajectory npz missing the format's arrays (render / mapping read it)"""
    path = tmp_path / "press.npz"
    np.savez(path, markers=np.zeros((2, 127, 2)))
    with fault(ValueError, str(path), "rerun the simulate stage"):
        load_trajectory(path)


def test_simulate_fails_when_every_trajectory_diverged(tmp_path, monkeypatch, fault):
    """simulate with every environment diverged exits non-zero, writes no trajectory"""
    from omegaconf import OmegaConf

    from palpation.apps import simulate
    from palpation.config_check import app_main
    from palpation.twin.config import TwinConfig
    from palpation.twin.runner import BatchResult

    write_outputs(tmp_path, [record("trajectory_0000")], [])  # the previous, good run
    (tmp_path / "m").write_bytes(b"mesh")  # hashed into the set's request key; SensorMesh.load is faked below
    monkeypatch.setattr(simulate.SensorMesh, "load", staticmethod(lambda path: type("M", (), {"resolution": "x"})))
    monkeypatch.setattr(simulate, "run_batches", lambda mesh, twin, reqs, batch_size, **kw: [BatchResult(
        records=[], failed=[failed(r.name) for r in reqs], frames=0, wall_s=0.0)])
    cfg = OmegaConf.create({"twin": OmegaConf.structured(TwinConfig), "mesh": str(tmp_path / "m"), "set": "randomised",
                            "seed": 1,
                            "n_pairs": 1, "heading_offset_deg": 0.0, "batch_size": 2, "progress": False,
                            "max_frames": None, "track": False, "dataset": {"recentre_k_n": False},
                            "out": {"dir": str(tmp_path)}})
    with fault(SystemExit, "simulate", "all 2 trajectories diverged", str(tmp_path / "manifest.json"),
               "twin.integrator.dt"):
        app_main("simulate")(simulate.run)(cfg)
    assert list(tmp_path.glob("*.npz")) == []
    with pytest.raises(ValueError, match="lists no trajectory files"):
        load_sim(tmp_path / "manifest.json", "train")
