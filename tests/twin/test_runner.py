"""Batched trajectory runs on the coarse mesh: files, manifest, failures, determinism, the app."""

import gc
import json
import os
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from palpation.paths import REPO_ROOT
from palpation.twin.config import TwinConfig
from palpation.twin.output import load_trajectory, write_outputs
from palpation.twin.runner import EnvRequest, run_batch, run_batches, simulate_states
from palpation.twin.simulator import BatchedTwin
from palpation.twin.trajectory import plan_trajectory

ABSURD_E = 1e11  # Pa: far past the explicit step's stability limit, NaN within a few frames


def test_smoke_run_writes_valid_file_and_manifest(tmp_path, mesh, binding):
    reqs = [EnvRequest("press", vessel=True, seed=3, name="press_vessel"),
            EnvRequest("slide", heading_offset_deg=5.0, seed=3, name="slide_cut")]
    res = run_batch(mesh, TwinConfig(), reqs, binding, device="cpu", progress=False, max_frames=36)
    assert not res.failed and [r.name for r in res.records] == ["press_vessel", "slide_cut"]
    manifest = write_outputs(tmp_path, res.records, res.failed, meta={"set": "smoke"})

    press = load_trajectory(tmp_path / "press_vessel.npz")
    assert press["markers"].shape == (36, 127, 2) and press["markers"].dtype == np.float32
    assert np.isfinite(press["markers"]).all()
    assert press["labels"].dtype == np.int8 and press["centreline_px"].shape == (36, 50, 2)
    assert np.array_equal(press["T_BA"], plan_trajectory("press").T_BA)  # tip node is the origin
    assert press["contact"][-1] and not press["contact"][0]  # the press reaches the vessel
    assert press["labels"][~press["contact"]].sum() == 0 and press["labels"].sum() > 0
    # frame 0 does not move, so the markers sit at their bound rest positions
    assert np.abs(press["markers"][0] - press["rest_markers_px"]).max() < 0.05
    assert press["params"]["vessel"] is True and press["seed"] == 3 and press["kind"] == "press"

    slide = load_trajectory(tmp_path / "slide_cut.npz")  # cut at 36 frames: only its last frame
    assert list(slide["frame_index"]) == [35] and slide["params"]["heading_deg"] == pytest.approx(-85.0)
    doc = json.loads(manifest.read_text())
    assert [f["file"] for f in doc["files"]] == ["press_vessel.npz", "slide_cut.npz"] and doc["failed"] == []
    assert doc["format"] == "palpation-sim/1" and doc["set"] == "smoke"


def test_failed_env_is_listed_not_saved(tmp_path, mesh, binding):
    reqs = [EnvRequest("press", name="fine"), EnvRequest("press", E=ABSURD_E, name="absurd", seed=7)]
    res = run_batch(mesh, TwinConfig(), reqs, binding, device="cpu", progress=False, max_frames=6)
    assert [r.name for r in res.records] == ["fine"] and list(res.failed_mask) == [False, True]
    write_outputs(tmp_path, res.records, res.failed)
    assert sorted(p.name for p in tmp_path.glob("*.npz")) == ["fine.npz"]
    failed = json.loads((tmp_path / "manifest.json").read_text())["failed"]
    assert len(failed) == 1 and failed[0]["name"] == "absurd" and failed[0]["params"]["E"] == ABSURD_E
    assert failed[0]["seed"] == 7 and 0 <= failed[0]["detected_at_frame"] < 6


def test_simulate_states_last_frame_and_failures(mesh, binding):
    requests = [("press", {"vessel": True}), ("press", {"E": ABSURD_E})]
    markers, failed = simulate_states(mesh, TwinConfig(), requests, device="cpu", binding=binding)
    full = run_batch(mesh, TwinConfig(), [EnvRequest("press", vessel=True)], binding, device="cpu",
                     progress=False)
    assert list(failed) == [False, True] and np.isnan(markers[1]).all()
    assert np.array_equal(markers[0], full.records[0].markers[-1])  # batching does not change an env
    with pytest.raises(ValueError, match="unknown parameters"):
        simulate_states(mesh, TwinConfig(), [("press", {"young": 1.0})], binding=binding)


def test_batches_in_threads_give_the_same_records(mesh):
    slides = [EnvRequest("slide", heading_offset_deg=h, k_n=k, name=f"s{i}")
              for i, (h, k) in enumerate([(5.0, 2e3), (-3.0, 4e3), (0.0, 3e3), (8.0, 5e3)])]
    slides.insert(2, EnvRequest("slide", E=ABSURD_E, name="absurd"))
    mixed = [EnvRequest("press", vessel=True, name="p"), EnvRequest("twist_x", name="t")]
    one = run_batches(mesh, TwinConfig(), slides + mixed, 500, device="cpu", progress=False, max_frames=12,
                      workers=1)
    many = run_batches(mesh, TwinConfig(), slides + mixed, 5, device="cpu", progress=False, max_frames=12,
                       workers=3)
    assert len(one) == 1 and [len(r.failed_mask) for r in many] == [2, 2, 1, 2]  # the mixed batch is not cut
    recs = [r for res in many for r in res.records]
    assert [r.name for r in recs] == [r.name for r in one[0].records] == ["s0", "s1", "s2", "s3", "p", "t"]
    assert [(f.name, f.detected_at_frame) for res in many for f in res.failed] == \
        [(f.name, f.detected_at_frame) for f in one[0].failed] and one[0].failed[0].name == "absurd"
    for a, b in zip(one[0].records, recs):
        for key in ("markers", "labels", "centreline_px", "contact", "T_BA", "frame_index"):
            assert getattr(a, key).tobytes() == getattr(b, key).tobytes(), f"{a.name}:{key}"


def test_leaving_the_batch_frees_the_twin(mesh, binding):
    """LockedBatch frees the twin's Warp arrays as it leaves, under the capture lock: no reference cycle through
    the per-frame kernels is left for the garbage collector to free in some thread's capture later."""
    gc.collect()
    gc.disable()
    try:
        res = run_batch(mesh, TwinConfig(), [EnvRequest("press", name="a")], binding, device="cpu", progress=False,
                        max_frames=3)
        alive = sum(isinstance(o, BatchedTwin) for o in gc.get_objects())
    finally:
        gc.enable()
    assert res.records[0].markers.shape == (3, 127, 2) and alive == 0


def compose_simulate(mesh_path: Path, out_dir: Path, workers: int = 0, extra: tuple = ()):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return compose(config_name="simulate", overrides=[
            "set=randomised", "n_pairs=1", "max_frames=84", "progress=false", "track=false",
            f"mesh={mesh_path}", f"out.dir={out_dir}", f"workers={workers}", *extra])


def test_a_set_with_the_same_request_is_copied_not_simulated(tmp_path, mesh):
    """reuse=[manifest]: the same draws, twin and mesh copy the finished set byte for byte (rule simulate_dataset and
    the chosen candidate's set), hard-linked on one file system; another seed or twin parameter simulates anew; a
    rewrite of the source leaves the copy as it was; a bad path is a one-line error."""
    from palpation.apps.simulate import run

    mesh_path = tmp_path / "mesh.npz"
    mesh.save(mesh_path)
    first = run(compose_simulate(mesh_path, tmp_path / "a"))
    source = Path(first["manifest"])
    copied = run(compose_simulate(mesh_path, tmp_path / "b", extra=(f"reuse=[{source}]",)))
    assert copied["reused"] == 1 and copied["n_files"] == 2
    a, b = json.loads(source.read_text()), json.loads(Path(copied["manifest"]).read_text())
    assert b["reused_from"] == str(source) and b["request_key"] == a["request_key"] and b["files"] == a["files"]
    for name in ("trajectory_0000.npz", "trajectory_0001.npz"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    for extra in (("seed=7",), ("twin.contact.c_n=5.0",)):
        other = run(compose_simulate(mesh_path, tmp_path / "c", extra=(f"reuse=[{source}]", *extra)))
        assert other["reused"] == 0 and "reused_from" not in json.loads(Path(other["manifest"]).read_text())
    # the copy is a hard link here (one file system); rewriting the source set replaces its files, not the copy's
    before = (tmp_path / "b" / "trajectory_0000.npz").read_bytes()
    assert os.path.samefile(tmp_path / "a" / "trajectory_0000.npz", tmp_path / "b" / "trajectory_0000.npz")
    run(compose_simulate(mesh_path, tmp_path / "a", extra=("seed=7",)))
    assert (tmp_path / "b" / "trajectory_0000.npz").read_bytes() == before != (tmp_path / "a" / "trajectory_0000.npz").read_bytes()
    with pytest.raises(FileNotFoundError, match="Sim manifest .*nope.json not found; name manifest.json files of finished sets in `reuse`"):
        run(compose_simulate(mesh_path, tmp_path / "d", extra=(f"reuse=[{tmp_path / 'nope.json'}]",)))


def test_app_same_seed_is_bit_identical(tmp_path, mesh):
    from palpation.apps.simulate import run, trajectory_set

    mesh_path = tmp_path / "mesh.npz"
    mesh.save(mesh_path)
    outs = []
    for rep, workers in (("a", 1), ("b", 2)):  # and the threads (twin.runner.run_batches) change no bit
        summary = run(compose_simulate(mesh_path, tmp_path / rep, workers))
        assert summary["n_files"] == 2 and summary["n_failed"] == 0
        outs.append(tmp_path / rep)
    for name in ("trajectory_0000.npz", "trajectory_0001.npz"):
        a, b = load_trajectory(outs[0] / name), load_trajectory(outs[1] / name)
        for key in ("markers", "labels", "centreline_px", "contact", "T_BA", "frame_index"):
            assert a[key].tobytes() == b[key].tobytes(), f"{name}:{key} differs between identical runs"
    first = load_trajectory(outs[0] / "trajectory_0000.npz")
    assert list(first["frame_index"]) == [81, 82, 83] and first["params"]["vessel"] is True
    reqs = trajectory_set("randomised", 42, n_pairs=2)  # SPEC §7 check values
    assert [round(r.heading_offset_deg, 2) for r in reqs] == [8.22, 5.92, 7.83, -1.49]
    assert [round(r.k_n * 5) for r in reqs[:2]] == [24750, 9238] and round(reqs[0].c_n, 1) == 85.9


def test_k_n_range_recentres_on_the_fit():
    from palpation.apps.simulate import K_N_REF_RANGE, k_n_draw_range, trajectory_set

    assert k_n_draw_range() == K_N_REF_RANGE
    lo, hi = k_n_draw_range(94908.307)
    assert np.isclose(np.sqrt(lo * hi), 94908.307) and np.isclose(hi / lo, 10.0)
    reqs = trajectory_set("randomised", 42, n_pairs=3, k_n_ref_range=(lo, hi))
    assert all(lo / 5 <= r.k_n <= hi / 5 for r in reqs)  # twin k_n = reference / 5
    with pytest.raises(ValueError, match="recentre_k_n"):
        k_n_draw_range(0.0)
