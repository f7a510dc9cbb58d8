"""Schema of the vessel_maps app's config (conf/vessel_maps.yaml starts with `defaults: [base_vessel_maps]`).

The values live in the YAML file (MISSING here); the dataclasses give every key a name and a type, so a
typo or an unknown key fails when Hydra composes the config. `scores` maps a configuration name (A-to-B,
...) to an explicit scores.npz; its keys are checked against the known configurations by the app.
Each numeric or list field carries its range (config_ranges), checked before the app runs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from palpation.config_ranges import SEEDS, Choice, Int, ListOf, Num, ranged
from palpation.mapping.pipeline import TEST_DATASET


@dataclass
class RunsSchema:
    root: str = MISSING  # <root>/<config>/L<clip_len>/seed<seed>/
    seeds: List[int] = ranged(MISSING, SEEDS)


@dataclass
class TestSetsSchema:
    sim: str = MISSING
    silicone: str = MISSING
    meat: str = MISSING


@dataclass
class SimMapsSchema:
    source: str = ranged(MISSING, Choice("test", "slide"))
    slide_manifest: str = MISSING
    max_maps: Optional[int] = ranged(MISSING, Int(ge=1, null=True))  # null: all
    vessel_only: bool = MISSING
    batch_size: int = ranged(MISSING, Int(ge=1))


@dataclass
class SweepLayoutSchema:
    """palpation.mapping.silicone_poses.SweepLayout; a null mirror_sum is measured from the dots."""

    path_spacing_mm: float = ranged(MISSING, Num(gt=0))
    centre_x_mm: float = ranged(MISSING, Num())
    centre_y_mm: float = ranged(MISSING, Num())
    mirror_sum: Optional[float] = ranged(MISSING, Num(gt=0, null=True))
    direction0_sign: float = ranged(MISSING, Choice(-1.0, 1.0))
    path0_side: float = ranged(MISSING, Choice(-1.0, 1.0))


@dataclass
class ThresholdSchema:
    tolerance_mm: float = ranged(MISSING, Num(gt=0))
    min_precision: float = ranged(MISSING, Num(gt=0, le=1))
    min_pixels: int = ranged(MISSING, Int(ge=0))


@dataclass
class VesselMapsConfig:
    profile: str = MISSING
    out_dir: str = MISSING
    clip_len: int = ranged(MISSING, Int(ge=1))
    configs: List[str] = ranged(MISSING, ListOf(Choice(*TEST_DATASET), unique=True))
    runs: RunsSchema = field(default_factory=RunsSchema)
    scores: Dict[str, Optional[str]] = field(default_factory=dict)
    data: TestSetsSchema = field(default_factory=TestSetsSchema)
    sim: SimMapsSchema = field(default_factory=SimMapsSchema)
    silicone_layout: SweepLayoutSchema = field(default_factory=SweepLayoutSchema)
    threshold: ThresholdSchema = field(default_factory=ThresholdSchema)
    max_grid_px: int = ranged(MISSING, Int(ge=1))
    device: str = MISSING
    track: bool = MISSING
    progress: bool = MISSING


ConfigStore.instance().store(name="base_vessel_maps", node=VesselMapsConfig)
