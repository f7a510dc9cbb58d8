"""conf_files: the conf/ files a Hydra app composes, which the Snakemake rules declare as inputs."""

from palpation.confdeps import conf_files
from palpation.paths import REPO_ROOT


def write(root, rel, text):
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_follows_defaults_and_choices(tmp_path):
    write(tmp_path, "app.yaml", "defaults:\n  - twin: quick\n  - preset: small\n  - experiment: null\n  - _self_\n")
    write(tmp_path, "twin/quick.yaml", "defaults:\n  - base_twin\n  - mesh: coarse\n  - _self_\n")
    for mesh in ("coarse", "fine"):
        write(tmp_path, f"twin/mesh/{mesh}.yaml", "resolution: x\n")
    write(tmp_path, "preset/small.yaml", "defaults:\n  - big\n  - _self_\n")
    write(tmp_path, "preset/big.yaml", "n: 1\n")
    write(tmp_path, "preset/other.yaml", "n: 2\n")
    write(tmp_path, "experiment/e1.yaml", "# @package _global_\ndefaults:\n  - override /model: m1\n")
    write(tmp_path, "model/m1.yaml", "w: 1\n")
    files = conf_files("app", conf_dir=tmp_path)
    assert files == sorted(str(tmp_path / f) for f in ("app.yaml", "twin/quick.yaml", "twin/mesh/coarse.yaml",
                                                      "preset/small.yaml", "preset/big.yaml"))
    chosen = conf_files("app", {"twin/mesh": "fine", "experiment": "e1", "preset": None}, conf_dir=tmp_path)
    assert chosen == sorted(str(tmp_path / f) for f in ("app.yaml", "twin/quick.yaml", "twin/mesh/fine.yaml",
                                                       "experiment/e1.yaml", "model/m1.yaml"))


def test_repository_configs(monkeypatch):
    monkeypatch.chdir(REPO_ROOT)
    train = conf_files("train", {"experiment": "C-to-B", "model": "compact", "recipe": "reference"})
    assert train == ["conf/experiment/C-to-B.yaml", "conf/model/compact.yaml", "conf/recipe/reference.yaml",
                     "conf/train.yaml"]
    loop = conf_files("loop", {"loop": "paper", "twin/mesh": "reference"})
    assert "conf/loop/quick.yaml" in loop and "conf/twin/mesh/coarse.yaml" not in loop  # paper inherits quick
