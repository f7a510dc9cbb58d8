"""Typed calibration settings (Hydra structured config `base_calibration`, conf/calibration/*.yaml).

Parameter names are those of the registry in calibration.params, in the units it lists (E in Pa,
k_n_ref in the reference's x5 units, ...). Everything is checked by `CalibrationConfig.validate`
and `calibration.params.check_space` before the twin is built.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from hydra.core.config_store import ConfigStore

from palpation import paper
from palpation.calibration.objective import ANGLE_SOURCES, GEOMETRIES, INTERACTIONS
from palpation.calibration.params import REGISTRY
from palpation.calibration.search import ParamSpec
from palpation.config_ranges import SEED, Choice, DictOf, Int, ListOf, Num, Text, ranged


@dataclass
class SearchParam:
    """One searched name; low / high / log left out (null) take the registry's (twin.parameters)."""

    name: str = ranged("E", Text())
    low: Optional[float] = ranged(None, Num(null=True))
    high: Optional[float] = ranged(None, Num(null=True))
    log: Optional[bool] = None


@dataclass
class PaperParams:
    """The paper's adopted twin (SPEC §6.4): E rounded to 881.4 kPa, k_n 94,908 reference units."""

    E: float = ranged(paper.E, Num(gt=0))
    k_n_ref: float = ranged(paper.K_N_REF, Num(gt=0))


@dataclass
class CalibrationConfig:
    # project (mean photo MAE, minimised) | reference (SPEC §6.2, maximised)
    objective: str = ranged("project", Choice("project", "reference"))
    params: list[SearchParam] = ranged(rule=ListOf(), factory=lambda: [SearchParam("E", 1e5, 1e6, True)])  # SPEC §6.3
    fixed: dict[str, float] = ranged(rule=DictOf(Num()), factory=dict)  # registry name -> value held in every trial
    interactions: list[str] = ranged(rule=ListOf(Choice(*INTERACTIONS), unique=True),
                                     factory=lambda: list(INTERACTIONS))
    # one interaction left out of the fit (reported, not fitted)
    holdout: Optional[str] = ranged(None, Choice(*INTERACTIONS, null=True))
    # photo: depth/angle from the file names; canonical: SPEC §4.1
    geometry: str = ranged("photo", Choice(*GEOMETRIES))
    twist_z_angle: str = ranged("reference", Choice(*ANGLE_SOURCES))  # reference: 30 deg (quirk 5); filename: 90 deg
    sampler: str = ranged("gp", Choice("gp", "tpe", "random"))  # gp | tpe | random (calibration.search.make_sampler)
    seed: int = ranged(42, SEED)
    n_trials: int = ranged(10, Int(ge=1))
    n_startup: int = ranged(5, Int(ge=0))  # random trials, proposed and simulated as one batch
    batch_size: int = ranged(1, Int(ge=1))  # proposals per batch after the startup (1 = the reference's sequential GP)
    worst_px: float = ranged(165.0, Num(gt=0))  # project: the score of a diverged trial (3 marker spacings)
    split_by_kind: str = "auto"  # one twin run per interaction: auto (= on CPU), true, false
    # reference objective (SPEC §6.2)
    heading_seed: int = ranged(42, SEED)  # the one heading draw per run: +8.22 deg
    trigger_px: float = ranged(55.0, Num(gt=0))
    cap_frames: int = ranged(400, Int(ge=1))
    norm_px: float = ranged(165.0, Num(gt=0))
    worst_value: float = ranged(-1.0, Num())
    paper: PaperParams = field(default_factory=PaperParams)
    max_frames: Optional[int] = ranged(None, Int(ge=1, null=True))  # cut every trajectory (smoke tests only)

    def space(self) -> list[ParamSpec]:
        """The search space; a bound or log flag left null comes from the registry (calibration.params)."""
        out = []
        for p in self.params:
            low, high, log = p.low, p.high, p.log
            if None in (low, high, log):
                if p.name not in REGISTRY:  # the wording of search.validate_space, which checks the rest
                    raise ValueError(f"calibration.params: unknown parameter '{p.name}'; known: {sorted(REGISTRY)}")
                entry = REGISTRY[p.name]
                low, high = entry.low if low is None else low, entry.high if high is None else high
                log = entry.log if log is None else log
            out.append(ParamSpec(p.name, float(low), float(high), bool(log)))
        return out

    def fit_interactions(self) -> list[str]:
        """The photos the objective scores (the reference objective scores only the slide photo)."""
        if self.objective == "reference":
            return ["slide"]
        return [k for k in self.interactions if k != self.holdout]

    def validate(self) -> "CalibrationConfig":
        if self.objective not in ("project", "reference"):
            raise ValueError(f"calibration.objective must be 'project' or 'reference', "
                             f"got '{self.objective}'")
        if self.holdout is not None and self.holdout not in self.interactions:
            raise ValueError(f"calibration.holdout='{self.holdout}' is not one of calibration.interactions "
                             f"{list(self.interactions)}")
        if not self.fit_interactions():
            raise ValueError("calibration: holding out the only interaction leaves nothing to fit")
        if self.geometry not in GEOMETRIES or self.twist_z_angle not in ANGLE_SOURCES:
            raise ValueError(f"calibration.geometry must be one of {GEOMETRIES} and twist_z_angle one of "
                             f"{ANGLE_SOURCES}, got '{self.geometry}', '{self.twist_z_angle}'")
        if self.n_trials < 1 or self.n_startup < 0 or self.batch_size < 1:
            raise ValueError(f"calibration: need n_trials >= 1, n_startup >= 0, batch_size >= 1, got "
                             f"{self.n_trials}, {self.n_startup}, {self.batch_size}")
        if str(self.split_by_kind).lower() not in ("auto", "true", "false"):
            raise ValueError(f"calibration.split_by_kind must be auto, true or false, "
                             f"got {self.split_by_kind}")
        return self

    def split(self, device: str) -> bool:
        mode = str(self.split_by_kind).lower()
        return device.startswith("cpu") if mode == "auto" else mode == "true"


def register_configs() -> None:
    cs = ConfigStore.instance()
    cs.store(group="calibration", name="base_calibration", node=CalibrationConfig)


register_configs()
