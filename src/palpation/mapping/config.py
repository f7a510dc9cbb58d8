"""Schema of the vessel_maps app's config (conf/vessel_maps.yaml starts with `defaults: [base_vessel_maps]`).

The values live in the YAML file (MISSING here); the dataclasses give every key a name and a type, so a
typo or an unknown key fails when Hydra composes the config. `scores` maps a configuration name (A-to-B,
...) to an explicit scores.npz; its keys are checked against the known configurations by the app.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING


@dataclass
class RunsSchema:
    root: str = MISSING  # <root>/<config>/L<clip_len>/seed<seed>/
    seeds: List[int] = MISSING


@dataclass
class TestSetsSchema:
    sim: str = MISSING
    silicone: str = MISSING
    meat: str = MISSING


@dataclass
class SimMapsSchema:
    source: str = MISSING  # test | slide
    slide_manifest: str = MISSING
    max_maps: Optional[int] = MISSING
    vessel_only: bool = MISSING
    batch_size: int = MISSING


@dataclass
class SweepLayoutSchema:
    """palpation.mapping.silicone_poses.SweepLayout; a null mirror_sum is measured from the dots."""

    path_spacing_mm: float = MISSING
    centre_x_mm: float = MISSING
    centre_y_mm: float = MISSING
    mirror_sum: Optional[float] = MISSING
    direction0_sign: float = MISSING
    path0_side: float = MISSING


@dataclass
class ThresholdSchema:
    tolerance_mm: float = MISSING
    min_precision: float = MISSING
    min_pixels: int = MISSING


@dataclass
class VesselMapsConfig:
    profile: str = MISSING
    out_dir: str = MISSING
    clip_len: int = MISSING
    configs: List[str] = MISSING
    runs: RunsSchema = field(default_factory=RunsSchema)
    scores: Dict[str, Optional[str]] = field(default_factory=dict)
    data: TestSetsSchema = field(default_factory=TestSetsSchema)
    sim: SimMapsSchema = field(default_factory=SimMapsSchema)
    silicone_layout: SweepLayoutSchema = field(default_factory=SweepLayoutSchema)
    threshold: ThresholdSchema = field(default_factory=ThresholdSchema)
    max_grid_px: int = MISSING
    device: str = MISSING
    tracking: bool = MISSING
    progress: bool = MISSING


ConfigStore.instance().store(name="base_vessel_maps", node=VesselMapsConfig)
