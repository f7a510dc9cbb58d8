"""Candidate twins of the downstream judge (issue 12, docs/slides.md "Twin on the task") on the real slides.

* A slide-loop fold's twin as a twin option (twin_fit/fitted.yaml, package twin, the calibration's
  mechanism): the fold's final parameters (slide_loop.json) on the slide loop's base twin, with the compliant
  phantom (foundation) switched on, so that a Sim set is simulated with what the fold fitted.
* Any twin replayed along the slides its fitting never saw: the trials of the slide loop's cut, less the
  fold's own for a fold twin, in the real scene (slides.replay: compliant phantom, the photo's vessels), scored
  by the motion MAE and the over-/off-vessel ratio exactly as the slide loop scores its held-out fold.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from palpation.io import save_text
from palpation.readers import read_json
from palpation.slides.folds import FOLDS, other
from palpation.slides.replay import SCENE_PARAMETERS, SCHEDULE_KEYS, frame_mae, vessel_ratio
from palpation.twin.config import TwinConfig
from palpation.twin.parameters import PARAMETERS


def read_slide_loop(path: str | Path) -> dict:
    data = read_json(path, "rerun rule slide_loop (palpation.apps.slide_loop)")
    for key in ("folds", "params", "size"):
        if key not in data:
            raise ValueError(f"{path}: no `{key}` (not a slide_loop.json of palpation.apps.slide_loop); "
                             "rerun rule slide_loop")
    return data


def fold_params(loop: dict, fold: str) -> dict[str, float]:
    """The fold's twin parameters after its last kept round (registry names; the scene's are scene_params')."""
    if fold not in FOLDS:
        raise ValueError(f"unknown fold '{fold}'; use one of {FOLDS}")
    return {k: float(v) for k, v in loop["params"][fold][-1].items() if k not in SCENE_PARAMETERS}


def scene_params(loop: dict, fold: str | None) -> dict[str, float]:
    """The real scene as fold `fold` fitted it (its phantom slope; {} for no fold): every candidate twin is
    replayed on a trial in the scene fitted on the other fold's trials, as the slide loop scored it."""
    if fold is None:
        return {}
    return {k: float(v) for k, v in loop["params"][fold][-1].items() if k in SCENE_PARAMETERS}


def twin_overrides(params: dict[str, float]) -> dict[str, dict]:
    """Registry parameters -> TwinConfig sections and fields, the compliant phantom switched on."""
    out: dict[str, dict] = {"contact": {"phantom_contact": True, "phantom_model": "foundation"}}
    for name, value in params.items():
        if name not in PARAMETERS:
            raise ValueError(f"slide_loop.json: unknown parameter '{name}' (palpation.twin.parameters)")
        p = PARAMETERS[name]
        out.setdefault(p.section, {})[p.field] = float(value) * p.scale
    return out


def write_fold_twin(loop: dict, fold: str, path: str | Path, source: str) -> dict:
    """twin_fit option of one fold's twin; returns its overrides."""
    over = twin_overrides(fold_params(loop, fold))
    head = (f"# @package twin\n# The slide loop's fold-{fold} twin (fitted on Silicone trials {loop['folds'][fold]}), "
            f"from {source}.\n# Load with: hydra.searchpath=[file://<dir above twin_fit>] +twin_fit=fitted\n")
    save_text(path, head + yaml.safe_dump(over, sort_keys=True))
    return over


def schedule_of(cfg: TwinConfig) -> dict[str, float]:
    """The twin's mount depth offset and marker anchor as the replay's schedule values (registry units)."""
    return {k: PARAMETERS[k].default(cfg) for k in SCHEDULE_KEYS if k in PARAMETERS}


def heldout_trials(loop: dict, fold: str | None) -> tuple[list[int], list[int]]:
    """(trials a twin is scored on, trials it was fitted on), 1-based, within the slide loop's cut."""
    if fold is None:
        return sorted(t for f in FOLDS for t in loop["folds"][f]), []
    return list(loop["folds"][other(fold)]), list(loop["folds"][fold])


def score(markers: np.ndarray, failed: np.ndarray, sset) -> dict:
    """Per-trial motion MAE and the vessel ratios of one twin's replay (markers (T, F, 127, 2))."""
    if failed.any():
        raise ValueError(f"the twin diverged on trial(s) {np.nonzero(failed)[0].tolist()} of the replay; "
                         "its held-out slide MAE is undefined (check the twin option's parameters)")
    return {"mae_px": frame_mae(markers, sset).tolist(), "vessel_ratio_sim": vessel_ratio(markers, sset.labels),
            "vessel_ratio_real": vessel_ratio(sset.markers, sset.labels)}
