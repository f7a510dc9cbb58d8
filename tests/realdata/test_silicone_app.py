"""Smoke test of the Silicone Hydra app on a tiny configuration (2 frames of one video)."""

import json

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from palpation.apps import silicone as app
from palpation.paths import REPO_ROOT


def _cfg(overrides):
    GlobalHydra.instance().clear()
    with initialize_config_dir(version_base="1.3", config_dir=str(REPO_ROOT / "conf")):
        return compose(config_name="silicone", overrides=overrides)


def test_app_builds_a_tiny_set(results_tmp):
    cfg = _cfg([f"out.dir={results_tmp}/silicone", "videos=[1]", "n_frames=2", "track=false",
                "overview=[[1,2]]"])
    meta = app.run(cfg)
    out = results_tmp / "silicone"
    for name in ("silicone.npz", "silicone.json", "silicone_overview.png", "silicone_overview.pdf"):
        assert (out / name).is_file()
    with np.load(out / "silicone.npz") as data:
        assert data["markers"].shape == (1, 2, 127, 2) and data["markers"].dtype == np.float32
        assert data["labels"].dtype == np.int8 and data["found"].dtype == bool
    saved = json.loads((out / "silicone.json").read_text())
    assert saved["videos"][0]["frame_index"] == [4, 9]
    assert saved["videos"][0]["sweep"] == "metadata_0.0_0.0"
    assert meta["summary"]["markers_per_frame_min"] == 127


def test_app_rejects_unknown_task_and_detector_typo(results_tmp):
    with pytest.raises(ValueError, match="unknown task"):
        app.run(_cfg(["task=oops"]))
    with pytest.raises(TypeError, match="max_step"):
        app.run(_cfg([f"out.dir={results_tmp}", "videos=[1]", "n_frames=1", "track=false",
                      "+detector.max_step=3"]))
