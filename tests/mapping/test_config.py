"""The vessel_maps config is typed by palpation.mapping.config: unknown keys and wrong types fail early."""

import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException

from palpation.apps.vessel_maps import run
from palpation.paths import REPO_ROOT


def compose_maps(overrides):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return compose(config_name="vessel_maps", overrides=overrides)


def test_schema_refuses_typos_and_wrong_types():
    cfg = compose_maps(["sim.max_maps=null", "scores.A-to-B=run/scores.npz"])
    assert cfg.sim.max_maps is None and cfg.scores["A-to-B"] == "run/scores.npz" and cfg.clip_len == 5
    with pytest.raises(ConfigCompositionException, match="Could not override 'threshold.min_precison'"):
        compose_maps(["threshold.min_precison=0.8"])
    with pytest.raises(ConfigCompositionException, match="Error merging override clip_len=five"):
        compose_maps(["clip_len=five"])


def test_scores_of_an_unknown_configuration(tmp_path):
    cfg = compose_maps(["+scores.B-to-A=run/scores.npz", f"out_dir={tmp_path}", "track=false"])
    with pytest.raises(ValueError, match=r"unknown config key\(s\) \['scores.B-to-A'\]"):
        run(cfg)
