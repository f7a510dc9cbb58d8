"""Damaged inputs through the apps (as their command lines run them: app_main around run(cfg)): the mesh, the photo
and Sim manifests, photos, videos and checkpoints end as the app's one-line error, exit status 1."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

import palpation.model.checkpoint  # noqa: F401  (torch: imported with the apps, at collection, not in a test)
from palpation.apps import loop, photos, render_twin, silicone, simulate, vessel_maps
from palpation.config_check import app_main
from palpation.graph.layout import rest_layout
from palpation.paths import REPO_ROOT
from palpation.twin.mesh import box_mesh


APPS = {m.__name__.rsplit(".", 1)[1]: m for m in (loop, photos, render_twin, silicone, simulate, vessel_maps)}
SCHEMAS = {"loop": ["loop", "twin"], "simulate": ["twin"], "vessel_maps": ["mapping"]}  # their structured configs


def composed(app: str, *overrides: str):
    import importlib

    for package in SCHEMAS.get(app, []):
        importlib.import_module(f"palpation.{package}.config")  # registers base_<app> / base_twin
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return compose(config_name=app, overrides=list(overrides))


def run_app(app: str, cfg):
    return app_main(app)(APPS[app].run)(cfg)


@pytest.fixture
def mesh(tmp_path):
    path = tmp_path / "mesh.npz"
    box_mesh().save(path)
    return path


def test_loop_app_truncated_mesh(tmp_path, mesh, fault):
    """the loop app given a truncated mesh file (was a raw zipfile.BadZipFile traceback)"""
    from palpation.markers.template import rest_template
    from palpation.measured import MeasuredState, make_measured_set, save_measured_set

    rest = rest_template().astype(np.float32)
    states = [MeasuredState("rest", "r.jpg", "rest", 0.0), MeasuredState("press_d4", "p.jpg", "press", 4.0)]
    save_measured_set(tmp_path / "set", make_measured_set(np.stack([rest, rest + 1]), np.ones((2, 127), bool),
                                                          rest, states))
    mesh.write_bytes(mesh.read_bytes()[:900])
    cfg = composed("loop", f"mesh={mesh}", f"measured={tmp_path / 'set'}", "track=false", f"out.dir={tmp_path / 'o'}",
                   "loop.holdout=[]", "loop.effects=[camera]")
    with fault(SystemExit, "loop: error:", f"mesh file {mesh}", "not a readable npz archive", "snakemake"):
        run_app("loop", cfg)


def simulate_cfg(tmp_path, mesh, *extra):
    return composed("simulate", f"mesh={mesh}", "set=canonical", "track=false", "progress=false",
                    f"out.dir={tmp_path / 'sim'}", *extra)


def test_simulate_app_mesh_of_wrong_type(tmp_path, mesh, fault):
    """the simulate app given a mesh whose tets are floats"""
    arrays = dict(np.load(mesh))
    arrays["tets"] = arrays["tets"].astype(np.float64)
    np.savez(mesh, **arrays)
    with fault(SystemExit, "simulate: error:", f"mesh file {mesh}", "`tets` has dtype float64", "snakemake"):
        run_app("simulate", simulate_cfg(tmp_path, mesh))
    assert not (tmp_path / "sim").exists()  # refused before any output


def test_simulate_app_reuse_manifest_row_without_file(tmp_path, mesh, fault):
    """simulate's `reuse` naming a Sim manifest whose row has no file name"""
    manifest = tmp_path / "old" / "manifest.json"
    manifest.parent.mkdir()
    manifest.write_text(json.dumps({"files": [{"kind": "press", "seed": 1}], "request_key": "x"}))
    with fault(SystemExit, "simulate: error:", f"Sim manifest {manifest}", "files row 1", "reuse=[]"):
        run_app("simulate", simulate_cfg(tmp_path, mesh, f"reuse=[{manifest}]"))


def test_render_app_sim_manifest_unknown_kind(tmp_path, fault):
    """render_twin given a Sim manifest row of an unknown kind"""
    manifest = tmp_path / "manifest.json"
    np.savez(tmp_path / "t.npz", markers=np.zeros((1, 127, 2)))
    manifest.write_text(json.dumps({"files": [{"file": "t.npz", "kind": "twist_y"}]}))
    cfg = composed("render_twin", f"manifests=[{manifest}]", f"out.dir={tmp_path / 'out'}")
    with fault(SystemExit, "render_twin: error:", str(manifest), "kind 'twist_y'", "simulate stage"):
        run_app("render_twin", cfg)


def photos_cfg(tmp_path, *extra):
    return composed("photos", f"photos_dir={tmp_path / 'photos'}", "track=false", "figure=false",
                    "blob_counts=false", f"out.dir={tmp_path / 'out'}", *extra)


def test_photos_app_twist_row_without_angle(tmp_path, fault):
    """a photo manifest row `twist_x` with no angle (was accepted: the twin twisted by 20 deg instead)"""
    (tmp_path / "photos").mkdir()
    for name in ("rest.png", "tx.png"):
        (tmp_path / "photos" / name).write_bytes(b"")
    manifest = tmp_path / "manifest.csv"
    manifest.write_text("file,kind,depth,angle\nrest.png,rest,0,\ntx.png,twist_x,2,\n")
    with fault(SystemExit, "photos: error:", str(manifest), "row 2 column 'angle' is empty", "twist angle"):
        run_app("photos", photos_cfg(tmp_path, f"photos_manifest={manifest}", "template_photo=rest.png",
                                     "rest_photo=rest.png"))


def test_photos_app_twist_name_without_angle(tmp_path, fault):
    """a paper-style photo name `twist_x_press_depth=2_...` without `_angle=`"""
    folder = tmp_path / "photos"
    folder.mkdir()
    (folder / "sensor_default_state.png").write_bytes(b"")
    (folder / "twist_x_press_depth=2_slide_length=50.jpg").write_bytes(b"")
    with fault(SystemExit, "photos: error:", "twist_x_press_depth=2", "needs its angle", "photos_manifest"):
        run_app("photos", photos_cfg(tmp_path))


def test_photos_app_truncated_template_photo(tmp_path, fault):
    """the template photo cut short (OpenCV would decode the rest as grey)"""
    folder = tmp_path / "photos"
    folder.mkdir()
    photo = REPO_ROOT / "data/reference/photos/flat-tip/press_press_depth=4_angle=10_slide_length=50_timestamp=" \
                        "2025-08-30-21-23-31.jpg"
    (folder / photo.name).write_bytes(photo.read_bytes()[:60_000])
    cfg = photos_cfg(tmp_path, f"template_photo='{photo.name}'", f"rest_photo='{photo.name}'")
    with fault(SystemExit, "photos: error:", str(folder / photo.name), "cannot be decoded", "restore it"):
        run_app("photos", cfg)


def test_silicone_app_damaged_video(tmp_path, fault):
    """the silicone app given an annotation video that is not a video"""
    video = tmp_path / "dataset_annotations_silicone.mp4"
    video.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 4)
    cfg = composed("silicone", f"video={video}", "videos=[1]", "n_frames=1", "progress=false", "figure=false",
                   "track=false", f"out.dir={tmp_path / 'out'}")
    with fault(SystemExit, "silicone: error:", str(video), "cannot be decoded", "data/reference/videos/"):
        run_app("silicone", cfg)


def test_silicone_check_truncated_set(tmp_path, fault):
    """silicone task=check given a truncated silicone.npz"""
    out = tmp_path / "out"
    out.mkdir()
    (out / "silicone.npz").write_bytes(b"PK\x03\x04" + b"\x00" * 40)
    cfg = composed("silicone", "task=check", "track=false", f"out.dir={out}")
    with fault(SystemExit, "silicone: error:", str(out / "silicone.npz"), "not a readable npz", "task=set"):
        run_app("silicone", cfg)


def test_vessel_maps_app_truncated_checkpoint(tmp_path, fault):
    """vessel_maps rescoring the vessel slide with a truncated checkpoint.pt"""
    from palpation.report.runs import run_dir

    run = run_dir(tmp_path / "train", "A-to-A", 5, 0)
    run.mkdir(parents=True)
    (run / "metrics.json").write_text(json.dumps({"test": {"ap": 0.5, "auroc": 0.5}}))
    (run / "checkpoint.pt").write_bytes(b"PK\x03\x04" + bytes(3000))  # a zip cut short after its first header
    cfg = composed("vessel_maps", "configs=[A-to-A]", f"runs.root={tmp_path / 'train'}", "runs.seeds=[0]",
                   "sim.source=slide", f"out_dir={tmp_path / 'maps'}", "track=false")
    with fault(SystemExit, "vessel_maps: error:", f"checkpoint {run / 'checkpoint.pt'}", "damaged or truncated",
               "rerun its train rule"):
        run_app("vessel_maps", cfg)


def test_train_data_meat_set_without_its_layout(tmp_path, fault):
    """a Meat set's .npz copied without the layout JSON beside it (its trials and splits)"""
    from palpation.graph.sources import load_meat
    from palpation.graph.synthetic import write_meat

    made = write_meat(tmp_path / "made" / "meat.npz", rest_layout("ideal"), n_frames=(9,) * 3, n_val=1)
    alone = tmp_path / "copied" / "meat.npz"
    alone.parent.mkdir()
    alone.write_bytes(Path(made).read_bytes())
    with fault(FileNotFoundError, "Meat layout", str(alone.with_suffix(".json")), "rerun the meat_set rule"):
        load_meat(alone, "all")


def test_train_data_sim_trajectory_of_wrong_shape(tmp_path, fault):
    """a Sim trajectory whose markers are (F, 120, 2): named with the file, not as sequence `sim/train`"""
    from palpation.graph.sources import load_sim
    from palpation.graph.synthetic import write_sim

    manifest = write_sim(tmp_path / "sim", rest_layout("ideal"), n_traj=2, n_frames=6)
    path = tmp_path / "sim" / "trajectory_0001.npz"
    arrays = dict(np.load(path))
    arrays["markers"] = arrays["markers"][:, :120]
    np.savez(path, **arrays)
    with fault(ValueError, str(path), "`markers` has shape", "expected (N, 127, 2)", "simulate_dataset"):
        load_sim(manifest, "all")
