"""Unknown config keys are refused before any work, naming the key, the app and a close existing key."""

import dataclasses

import pytest
from omegaconf import OmegaConf

from palpation.config_check import ConfigKeyError, app_main, check_config
from palpation.paths import REPO_ROOT

APPS = tuple(sorted(p.stem for p in (REPO_ROOT / "conf").glob("*.yaml")))  # every app has conf/<app>.yaml


@pytest.mark.parametrize("app", APPS)
def test_shipped_configs_pass(app, hydra_job):
    check_config(hydra_job(app), app)


def test_added_key_in_a_structured_config(hydra_job, fault):
    """`+twin.Emod=1`: Hydra accepts it, to_object would drop it"""
    cfg = hydra_job("simulate", ["+twin.Emod=1"])
    with fault(ConfigKeyError, "'twin.Emod'", "+twin.Emod=1", "palpation.apps.simulate",
               "did you mean twin.material.E?"):
        check_config(cfg, "simulate")


def test_added_key_in_a_plain_section(hydra_job, fault):
    """`+train.epoch=1`: was a raw TypeError in TrainConfig"""
    cfg = hydra_job("train", ["+train.epoch=1"])
    with fault(ConfigKeyError, "'train.epoch'", "palpation.apps.train", "did you mean train.epochs?"):
        check_config(cfg, "train")


def test_force_added_unknown_key(hydra_job, fault):
    """`++loop.round=2` names no existing key"""
    cfg = hydra_job("loop", ["++loop.round=2"])
    with fault(ConfigKeyError, "'loop.round'", "++loop.round=2", "palpation.apps.loop"):
        check_config(cfg, "loop")


def test_appended_config_group_is_fine(hydra_job, tmp_path):
    """`+twin_fit=fitted` (a calibration's fit, a config group on a search path) is not a key"""
    (tmp_path / "twin_fit").mkdir()
    (tmp_path / "twin_fit" / "fitted.yaml").write_text("# @package twin\nmaterial:\n  E: 500000.0\n")
    cfg = hydra_job("simulate", [f"hydra.searchpath=[file://{tmp_path}]", "+twin_fit=fitted"])
    assert cfg.twin.material.E == 500000.0
    check_config(cfg, "simulate")


def test_force_added_existing_key_is_fine(hydra_job):
    check_config(hydra_job("train", ["++train.epochs=2", "seed=3"]), "train")


def test_unknown_key_forced_into_a_structured_section(fault):
    """a key forced into a structured section outside any override (as Hydra's `+` does it)"""
    from palpation.calibration.config import CalibrationConfig

    cfg = OmegaConf.create({"calibration": OmegaConf.structured(CalibrationConfig)})
    OmegaConf.update(cfg, "calibration.n_trails", 8, force_add=True)
    with fault(ConfigKeyError, "'calibration.n_trails'", "did you mean calibration.n_trials?"):
        check_config(cfg, "calibrate")


def test_plain_config_without_hydra_passes():
    check_config(OmegaConf.create({"train": {"epochs": 1}, "seed": 0}), "train")


def test_app_refuses_before_any_work(hydra_job, fault):
    """the app body never runs with an unknown key; the error is one line with exit status 1"""
    cfg = hydra_job("calibrate", ["+calibration.trials=3", "track=false"])
    ran = []
    with fault(SystemExit, "calibrate: error: unknown config key 'calibration.trials'"):
        app_main("calibrate")(ran.append)(cfg)
    assert ran == []


def test_check_sees_every_dataclass_field():
    """the check reads the fields the dataclass declares (no hand-kept list)"""
    from palpation.twin.config import TwinConfig

    cfg = OmegaConf.structured(TwinConfig)
    assert set(cfg.keys()) == {f.name for f in dataclasses.fields(TwinConfig)}
