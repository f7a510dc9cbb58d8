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
