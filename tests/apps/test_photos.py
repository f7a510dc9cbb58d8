"""Smoke test of the photos app: composes conf/photos.yaml and runs it into a temp folder."""

import json

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from palpation.apps.photos import run
from palpation.measured import load_measured_set
from palpation.paths import FLAT_TIP_PHOTOS, REPO_ROOT


def compose_photos(*overrides):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return compose(config_name="photos", overrides=[f"photos_dir={FLAT_TIP_PHOTOS}", *overrides])


def test_photos_app_writes_the_measured_set(tmp_path):
    cfg = compose_photos(f"out.dir={tmp_path}", "track=false", "blob_counts=false", "figure=false")
    summary = run(cfg)
    mset = load_measured_set(tmp_path / "measured_photos")
    assert mset.markers.shape == (6, 127, 2) and mset.found.all()
    assert mset.names[0] == "press_d0" and not mset.displacement[0].any()
    assert {s.trajectory for s in mset.states} == {"rest", "press", "twist_z", "twist_x", "slide"}
    rows = {r["name"]: r for r in summary["photos"]}
    assert all(r["n_markers"] == 127 for r in rows.values())
    # SPEC §13.2 displacement vs press d=0 and §15.8 undeformed baselines, within detector tolerance
    for name, row in rows.items():
        for key in ("disp_median_px", "disp_max_px", "baseline_mae_template_px", "baseline_mae_rest_photo_px"):
            if f"spec_{key}" in row:
                assert row[key] == pytest.approx(row[f"spec_{key}"], abs=1.0), (name, key)
    assert json.loads((tmp_path / "photo_summary.json").read_text())["photos"][0]["name"] == "press_d0"
    assert (tmp_path / "photo_summary.csv").read_text().count("\n") == 7


def test_wrong_count_names_the_photo(tmp_path):
    cfg = compose_photos(f"out.dir={tmp_path}", "track=false", "blob_counts=false", "figure=false",
                         "detector.ratio_max=0.3")
    with pytest.raises(ValueError, match=r"sensor_default_state.png: found \d+ markers, expected 127"):
        run(cfg)
    assert not any(tmp_path.iterdir())


def test_rest_photo_must_exist(tmp_path):
    cfg = compose_photos(f"out.dir={tmp_path}", "track=false", "rest_photo=nope.jpg")
    with pytest.raises(ValueError, match="nope.jpg"):
        run(cfg)
    assert np.all([not p.exists() for p in tmp_path.iterdir()])


def test_any_photo_set_with_a_manifest(tmp_path):
    """Photos under other names, described by a CSV or YAML manifest, give the paper-named run's markers."""
    import shutil

    from palpation.markers.manifest import paper_names
    from palpation.markers.photoset import list_photos

    paper = {info.name: info for info in paper_names(list_photos(FLAT_TIP_PHOTOS))}
    photos = tmp_path / "photos"
    photos.mkdir()
    rows = [("zero.jpg", "rest", "0", "", "press_d0"), ("template.png", "rest", "0", "", "sensor_default_state"),
            ("tw.jpg", "twist_x", "2", "20", "twist_x_d2_a20")]
    for file, *_, name in rows:
        shutil.copy(paper[name].path, photos / file)
    csv = tmp_path / "manifest.csv"
    csv.write_text("file,kind,depth,angle\n" + "".join(f"{f},{k},{d},{a}\n" for f, k, d, a, _ in rows))
    yml = tmp_path / "manifest.yaml"
    yml.write_text("photos:\n" + "".join(f"  - {{file: {f}, kind: {k}, depth: {d}, angle: {a or 'null'}}}\n"
                                         for f, k, d, a, _ in rows))
    ref = load_measured_set(run(compose_photos(f"out.dir={tmp_path}/ref", "track=false", "blob_counts=false",
                                               "figure=false")) and tmp_path / "ref/measured_photos")
    for manifest in (csv, yml):
        out = tmp_path / manifest.suffix[1:]
        run(compose_photos(f"photos_dir={photos}", f"photos_manifest={manifest}", "template_photo=template.png",
                           "rest_photo=zero.jpg", f"out.dir={out}", "track=false", "blob_counts=false",
                           "figure=false"))
        mset = load_measured_set(out / "measured_photos")
        assert [s.trajectory for s in mset.states] == ["rest", "rest", "twist_x"]
        assert mset.states[2].angle_deg == 20.0 and mset.states[2].depth_mm == 2.0 and mset.found.all()
        for state, (*_, name) in zip(mset.states, rows):
            np.testing.assert_array_equal(mset.markers[mset.names.index(state.name)],
                                          ref.markers[ref.names.index(name)])
