"""The training configurations as conf/ defines them, for the Snakemake workflow: each
conf/experiment/<name>.yaml composed over conf/train.yaml, exactly as `palpation.apps.train experiment=<name>`
composes it, gives the sets it trains and tests on and its model size; conf/train.yaml's `data:` gives the
dataset files. The overlays stay the only place a configuration is written down."""

from dataclasses import dataclass
from pathlib import Path

from hydra import compose, initialize_config_dir

from palpation.model import config as _train_schema  # noqa: F401 (registers base_train, which train.yaml extends)


@dataclass(frozen=True)
class Experiment:
    name: str
    train_on: str  # sim | silicone | meat
    test_on: str
    model: str  # large | compact (conf/model/<model>.yaml)

    @property
    def datasets(self) -> tuple[str, ...]:
        """The sets the run reads, training set first; A-to-A trains and tests on one (Sim)."""
        return tuple(dict.fromkeys((self.train_on, self.test_on)))


def experiments(conf_dir: str | Path = "conf") -> dict[str, Experiment]:
    """Every configuration under conf_dir/experiment/, by name, sorted."""
    conf = Path(conf_dir).resolve()
    names = sorted(p.stem for p in (conf / "experiment").glob("*.yaml"))
    if not names:
        raise FileNotFoundError(f"{conf / 'experiment'}: no experiment overlays (<name>.yaml); is conf_dir right?")
    with initialize_config_dir(config_dir=str(conf), version_base=None):
        cfgs = {name: compose("train", overrides=[f"experiment={name}"]) for name in names}
    return {name: Experiment(name, c.train_on, c.test_on, c.model.name) for name, c in cfgs.items()}


def dataset_files(conf_dir: str | Path = "conf") -> dict[str, str]:
    """The dataset files the training app reads by default (conf/train.yaml `data:`), by set name."""
    with initialize_config_dir(config_dir=str(Path(conf_dir).resolve()), version_base=None):
        return {name: str(path) for name, path in compose("train").data.items()}
