"""Typed configuration of the model and of one training run, and the schema of the train app's config.

`ModelConfig` and `TrainConfig` are what the library takes; the train app builds them at the edge. The
schema (`TrainAppConfig`, stored as `base_train`; conf/train.yaml starts with `defaults: [base_train]`)
types every key of the composed config, so a typo or an unknown key (`+train.epoch=1`) fails when Hydra
composes it. Values live in the YAML files (MISSING here); the schema only gives names and types, and
the choice keys (norm_stats, rotation, schedule, select_metric, calibration) are enums, so OmegaConf
refuses a value outside them at composition, naming the key (`recipe.schedule`) and the allowed values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from palpation.config_ranges import SEED, Choice, DictOf, Int, ListOf, Num, Text, ranged
from palpation.graph.align import METHODS as ALIGN_METHODS, STATS_FROM as ALIGN_STATS
from palpation.graph.augment import ROTATION_MODES


@dataclass  # not frozen: it is also the schema of the `model` group (OmegaConf cannot merge into frozen nodes)
class ModelConfig:
    """Widths of SPEC §9: large s=248 / L_d=256 / k=128, compact 56 / 64 / 32."""

    name: str = ranged("large", Text())
    encoder_width: int = ranged(248, Int(ge=1))  # s
    latent_width: int = ranged(256, Int(ge=1))  # L_d = s + type_dim
    skip_width: int = ranged(128, Int(ge=1))  # k
    type_dim: int = ranged(8, Int(ge=1))
    input_dropout: float = ranged(0.1, Num(ge=0, lt=1))
    dropout: float = ranged(0.3, Num(ge=0, lt=1))

    def __post_init__(self):
        if self.latent_width != self.encoder_width + self.type_dim:
            raise ValueError(f"model '{self.name}': latent_width ({self.latent_width}) must equal "
                             f"encoder_width + type_dim ({self.encoder_width} + {self.type_dim})")


# The choice keys of a recipe. OmegaConf matches a YAML string to an enum member's *name*, so names equal
# values; StrEnum members are those strings.
NormStats = StrEnum("NormStats", {m: m for m in ("sample", "full")})
Rotation = StrEnum("Rotation", {m: m for m in ROTATION_MODES})
Schedule = StrEnum("Schedule", {m: m for m in ("none", "step")})
SelectMetric = StrEnum("SelectMetric", {m: m for m in ("fg_iou", "ap")})
Calibration = StrEnum("Calibration", {m: m for m in ("none", "temperature", "platt", "cross_real")})
Align = StrEnum("Align", {m: m for m in ALIGN_METHODS})
AlignStats = StrEnum("AlignStats", {m: m for m in ALIGN_STATS})
SelectOn = StrEnum("SelectOn", {m: m for m in ("val", "other_real", "other_real_half")})
Pseudo = StrEnum("Pseudo", {m: m for m in ("none", "other_real", "test_set")})
DATASETS = ("sim", "silicone", "meat")  # train_on / test_on: the sets graph.sources.load_dataset reads
CHOICES = {"norm_stats": NormStats, "rotation": Rotation, "schedule": Schedule, "select_metric": SelectMetric,
           "calibration": Calibration, "align": Align, "align_stats": AlignStats, "select_on": SelectOn,
           "pseudo": Pseudo}


@dataclass(frozen=True)
class TrainConfig:
    """One training run (SPEC §10). `None` batches mean the whole split."""

    batch_size: int = 16
    epochs: int = 1
    train_batches: int | None = 152
    val_batches: int | None = 32
    lr: float = 1e-4
    weight_decay: float = 1e-4
    focal_gamma: float = 3.0
    norm_stats: str = "sample"  # sample (quirk 7: batch_size augmented clips) | full
    norm_clips: int | None = None  # clips for `sample`; None = batch_size
    rotation: str = "reference"  # none | reference (quirk 14) | consistent | lattice (ClipSet.gather)
    schedule: str = "none"  # none | step (StepLR(step_size, gamma), quirk 8)
    step_size: int = 64
    step_gamma: float = 0.5
    # robust-recipe switches (issue 15); the defaults are the reference recipe's (all off)
    jitter_px: float = 0.0  # Gaussian marker noise per coordinate, px (detector: < 0.2 px)
    marker_dropout: float = 0.0  # share of marker-frames held at the previous frame (missed detection)
    displacement_scale: float = 0.0  # per-clip displacement factor U(1 - s, 1 + s) about the rest layout
    patience: int | None = None  # early stopping: epochs without a better validation score; None = off
    select_metric: str = "fg_iou"  # validation score for checkpointing: fg_iou (at threshold) | ap
    # post-hoc: none | temperature | platt (on the validation split) | cross_real (Platt on the same models' scores on
    # the other real test set scored with them, also_test; never the run's own test set)
    calibration: str = "none"
    # opt-in input transform, off in every shipped recipe: each frame's whole-field translation taken off the
    # features (graph.features.without_common_motion; the real slides' drift that no twin reproduces)
    remove_common_motion: bool = False
    # transfer options (docs/transfer.md), off in every shipped recipe. align: the scored set's raw features mapped
    # onto the training clips' moments at scoring (graph.align: none | meanstd | coral) from the clips that
    # align_stats names (other_real: inductive; test_set / test_sequence: the scored set's own inputs, transductive).
    # select_on: the split that chooses the checkpoint, stops early and fits a calibration (val: the training
    # domain's; other_real: the labelled real set other than the scored one, its val trials if it is the training set;
    # other_real_half: its selection half, so the other half can score the method: model.domain.half_trials)
    align: str = "none"
    align_stats: str = "other_real"
    select_on: str = "val"
    # self-training (docs/transfer.md): the unlabelled clips of `pseudo` (other_real: the other real set, inductive;
    # test_set: the scored set's own, transductive) join the training set, pseudo-labelled where the teacher runs
    # in `pseudo_from` (one scores.npz per seed) agree (model.pseudo_labels.agreed_labels); their loss weighs
    # pseudo_weight, markers without an agreed label weigh 0
    pseudo: str = "none"
    pseudo_from: str | None = None
    pseudo_min_agree: float = 1.0
    pseudo_margin: float = 0.0
    pseudo_weight: float = 1.0
    restarts: int = 1  # starts per seed, the best on val kept (palpation.model.restarts); 1 = the seed alone
    threshold: float = 0.5
    device: str = "cpu"

    def __post_init__(self):
        # the app's values passed the schema's enums; this guards a TrainConfig built in code
        for key, kind in CHOICES.items():
            if getattr(self, key) not in kind.__members__:
                raise ValueError(f"{key}={getattr(self, key)!r}: use one of {list(kind.__members__)}")
        # ranges and the null-or-positive patience: no OmegaConf type expresses these
        if self.jitter_px < 0 or not 0 <= self.marker_dropout < 1 or not 0 <= self.displacement_scale < 1:
            raise ValueError("jitter_px must be >= 0, marker_dropout and displacement_scale in [0, 1); got "
                             f"{self.jitter_px}, {self.marker_dropout}, {self.displacement_scale}")
        if self.patience is not None and self.patience < 1:
            raise ValueError(f"patience must be >= 1 epoch or null (off), got {self.patience}")
        if (self.pseudo == "none") != (self.pseudo_from is None):
            raise ValueError(f"recipe.pseudo={self.pseudo} with recipe.pseudo_from={self.pseudo_from}: give both (a "
                             "teacher runs folder and other_real or test_set) or neither (pseudo=none, "
                             "pseudo_from=null)")
        if not 0.5 < self.pseudo_min_agree <= 1 or not 0 <= self.pseudo_margin < 0.5 or self.pseudo_weight <= 0:
            raise ValueError(f"recipe.pseudo_min_agree={self.pseudo_min_agree} must be in (0.5, 1], pseudo_margin="
                             f"{self.pseudo_margin} in [0, 0.5) and pseudo_weight={self.pseudo_weight} > 0")
        if self.batch_size < 1 or self.epochs < 1 or self.restarts < 1:
            raise ValueError(f"batch_size, epochs and restarts must be >= 1, got {self.batch_size}, {self.epochs}, "
                             f"{self.restarts}")


# ---- schema of conf/train.yaml (Hydra needs runtime types: Optional/Dict, not `int | None`) ----

@dataclass
class SizesSchema:
    """One model's sizes: recipe.sizes.<model> and the chosen `train` block."""

    batch_size: int = ranged(MISSING, Int(ge=1))
    epochs: int = ranged(MISSING, Int(ge=1))
    train_batches: Optional[int] = ranged(MISSING, Int(ge=1, null=True))  # null = the whole training split
    val_batches: Optional[int] = ranged(MISSING, Int(ge=1, null=True))


@dataclass
class RunSizesSchema(SizesSchema):
    restarts: int = ranged(MISSING, Int(ge=1))
    threshold: float = ranged(MISSING, Num(gt=0, lt=1))


@dataclass
class RecipeSchema:
    """conf/recipe/*.yaml: TrainConfig's recipe fields and the sizes per model."""

    name: str = MISSING
    lr: float = ranged(MISSING, Num(gt=0))
    weight_decay: float = ranged(MISSING, Num(ge=0))
    focal_gamma: float = ranged(MISSING, Num(ge=0))
    norm_stats: NormStats = MISSING
    norm_clips: Optional[int] = ranged(MISSING, Int(ge=1, null=True))
    rotation: Rotation = MISSING
    schedule: Schedule = MISSING
    step_size: int = ranged(MISSING, Int(ge=1))
    step_gamma: float = ranged(MISSING, Num(gt=0))
    jitter_px: float = ranged(MISSING, Num(ge=0))
    marker_dropout: float = ranged(MISSING, Num(ge=0, lt=1))  # as TrainConfig checks a run built in code
    displacement_scale: float = ranged(MISSING, Num(ge=0, lt=1))
    patience: Optional[int] = ranged(MISSING, Int(ge=1, null=True))
    select_metric: SelectMetric = MISSING
    calibration: Calibration = MISSING
    remove_common_motion: bool = MISSING
    align: Align = MISSING
    align_stats: AlignStats = MISSING
    select_on: SelectOn = MISSING
    pseudo: Pseudo = MISSING
    pseudo_from: Optional[str] = MISSING  # a teacher runs folder (docs/transfer.md); null with pseudo none
    pseudo_min_agree: float = ranged(MISSING, Num(gt=0.5, le=1))
    pseudo_margin: float = ranged(MISSING, Num(ge=0, lt=0.5))
    pseudo_weight: float = ranged(MISSING, Num(gt=0))
    sizes: Dict[str, SizesSchema] = ranged(MISSING, DictOf(min_len=1))


@dataclass
class TrainDataSchema:
    sim: str = MISSING
    silicone: str = MISSING
    meat: str = MISSING


@dataclass
class GraphSchema:
    rest: str = ranged(MISSING, Choice("template", "ideal"))


@dataclass
class TrainAppConfig:
    config_name: str = MISSING
    seed: int = ranged(MISSING, SEED)
    seeds: Optional[List[int]] = ranged(MISSING, ListOf(SEED, unique=True, null=True))  # null: train `seed` alone
    also_test: List[str] = ranged(MISSING, ListOf(Text(), 0, unique=True))  # with seeds: "<config name>:<test set>"
    also_uncalibrated: Optional[str] = MISSING  # with seeds: where the raw-score twins of the runs go
    # with seeds: "<align>:<align_stats>:<folder>", the same models' scores aligned that way, written there
    also_aligned: List[str] = ranged(MISSING, ListOf(Text(), 0, unique=True))
    clip_len: int = ranged(MISSING, Int(ge=1))
    device: str = MISSING
    train_on: str = ranged(MISSING, Choice(*DATASETS))
    test_on: str = ranged(MISSING, Choice(*DATASETS))
    data: TrainDataSchema = field(default_factory=TrainDataSchema)
    graph: GraphSchema = field(default_factory=GraphSchema)
    train: RunSizesSchema = field(default_factory=RunSizesSchema)
    model: ModelConfig = field(default_factory=ModelConfig)
    recipe: RecipeSchema = field(default_factory=RecipeSchema)
    track: bool = MISSING
    progress: bool = MISSING


ConfigStore.instance().store(name="base_train", node=TrainAppConfig)
