"""palpation.experiments: the training configurations the workflow reads from conf/experiment/."""

import shutil

import pytest

from palpation.experiments import Experiment, dataset_files, experiments
from palpation.paths import REPO_ROOT


def test_repository_experiments_are_the_overlays():
    found = experiments(REPO_ROOT / "conf")
    assert sorted(found) == sorted(p.stem for p in (REPO_ROOT / "conf" / "experiment").glob("*.yaml"))
    assert found["C-to-B"] == Experiment("C-to-B", train_on="meat", test_on="silicone", model="compact")
    assert found["A-to-A"].datasets == ("sim",) and found["A-to-C"].datasets == ("sim", "meat")
    assert dataset_files(REPO_ROOT / "conf") == {"sim": "results/sim/dataset/manifest.json",
                                                 "silicone": "results/data/silicone/silicone.npz",
                                                 "meat": "results/data/meat/meat.npz"}


def test_a_new_overlay_is_a_new_experiment(tmp_path):
    conf = shutil.copytree(REPO_ROOT / "conf", tmp_path / "conf")
    (conf / "experiment" / "C-to-A.yaml").write_text(
        "# @package _global_\ndefaults:\n  - override /model: compact\n\nconfig_name: C-to-A\ntrain_on: meat\n"
        "test_on: sim\n")
    assert experiments(conf)["C-to-A"] == Experiment("C-to-A", train_on="meat", test_on="sim", model="compact")


def test_missing_overlays_are_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no experiment overlays"):
        experiments(tmp_path)
