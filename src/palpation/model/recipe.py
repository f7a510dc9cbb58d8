"""The robust recipe's switches (issue 15, conf/recipe/robust.yaml) and how the ablation turns one off.

A switch names the TrainConfig fields it sets; turning it off puts those fields back to the reference
recipe's values, which are TrainConfig's defaults (conf/recipe/reference.yaml states the same values).
"""

from __future__ import annotations

import dataclasses

from palpation.model.config import TrainConfig

SWITCHES: dict[str, tuple[str, ...]] = {
    "norm_stats": ("norm_stats",),  # statistics and α from every training clip (quirk 7)
    "rotation": ("rotation",),  # consistent rotation (quirk 14)
    "jitter": ("jitter_px",),  # detector noise
    "dropout": ("marker_dropout",),  # missed detections
    "scale": ("displacement_scale",),  # displacement magnitude
    "early_stop": ("patience",),  # early stopping on the val split (the epochs stay)
    "select_ap": ("select_metric",),  # checkpoint by val AP instead of val FG IoU at 0.5
    "calibration": ("calibration",),  # post-hoc calibration on the val split
}
REFERENCE = {f.name: f.default for f in dataclasses.fields(TrainConfig)}
# switches that change only where training stops, which checkpoint is kept or how its scores are rescaled: their
# runs follow the full robust recipe's training epoch for epoch (same draws, same steps) as far as both ran
SAME_TRAJECTORY = ("early_stop", "select_ap", "calibration")


def _yaml(value) -> str:
    return "null" if value is None else str(value)


def switch_off(name: str) -> list[str]:
    """Hydra overrides that turn switch `name` of the recipe back to the reference values."""
    if name not in SWITCHES:
        raise ValueError(f"unknown recipe switch '{name}'; use one of {sorted(SWITCHES)} (palpation.model.recipe)")
    return [f"recipe.{field}={_yaml(REFERENCE[field])}" for field in SWITCHES[name]]
