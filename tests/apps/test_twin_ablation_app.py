"""The dataset-twin ablation table on hand-made run folders: one row per twin, means match the runs."""

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from palpation.apps.twin_ablation import run
from palpation.paths import REPO_ROOT
from palpation.report.twin_ablation import COLUMNS


def compose_cfg(overrides):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        return compose(config_name="twin_ablation", overrides=overrides)


def test_twin_ablation_table(tmp_path, fake_run):
    loop_root, cal_root, out = tmp_path / "train", tmp_path / "train" / "twin_calibrated", tmp_path / "report"
    for s in (0, 1, 2):
        fake_run(loop_root, "A-to-B", 5, s)
        fake_run(cal_root, "A-to-B", 7, s)  # another clip length: different scores than the loop runs
    cfg = compose_cfg([f"twins.loop={loop_root}", f"twins.calibrated={cal_root}", f"out_dir={out}",
                       "profile=quick"])
    with pytest.raises(FileNotFoundError, match="3 training run"):
        run(cfg)  # the calibrated runs exist at L = 7 only
    for s in (0, 1, 2):
        fake_run(cal_root, "A-to-B", 5, s + 10)
    with pytest.raises(FileNotFoundError):
        run(cfg)
    cfg = compose_cfg([f"twins.loop={loop_root}", f"twins.calibrated={loop_root}", f"out_dir={out}"])
    assert run(cfg) == {"loop": 3, "calibrated": 3}
    df = pd.read_csv(out / "twin_ablation.csv")
    assert tuple(df.columns) == COLUMNS and list(df.dataset_twin) == ["loop", "calibrated"]
    sweep = [pd.read_json(loop_root / "A-to-B" / "L5" / f"seed{s}" / "metrics.json").loc["auroc", "test"]
             for s in (0, 1, 2)]
    assert np.isclose(df.auroc_mean[0], np.mean(sweep)) and np.isclose(df.auroc_std[0], np.std(sweep, ddof=1))
    md = (out / "twin_ablation.md").read_text()
    assert "loop twin" in md and "calibrated twin" in md and "0.7789 ± 0.0043" in md


def test_twin_ablation_needs_a_twin(tmp_path):
    with pytest.raises(ValueError, match="twins"):
        run(compose_cfg(["~twins", "+twins={}", f"out_dir={tmp_path}"]))
