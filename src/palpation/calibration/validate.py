"""Validation (SPEC §6.4, §15.8): every interaction run vessel-free to its last waypoint and compared
with its photo, for (a) an undeformed sensor, (b) the paper's adopted parameters, (c) our fit.

(a) has two columns: the rest template (`sensor_default_state.png`, SPEC's "undeformed rest
markers") and the press d=0 photo. A third baseline, the twin's own undeformed markers (the template
bound to the mesh's dome nodes; several px off the template on a coarse mesh), separates what the
binding does from what the simulated deformation does. One twin call simulates (b) and (c) for every
interaction, plus twist_z at the other angle source (quirk 5: 30 deg as the reference, or the file
name's 90 deg).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from palpation.calibration.objective import Simulator, Target, marker_mae_px, target_geometry, undeformed_mae
from palpation.calibration.params import to_env
from palpation.camera import MM_PER_PX
from palpation.report.paper import CALIBRATION_MAE

# SPEC §15.8 (px): the reference twin and its two undeformed baselines
SPEC_TWIN_PX = {k: v["twin"] for k, v in CALIBRATION_MAE.items()}
SPEC_UNDEFORMED_PX = {k: v["undeformed"] for k, v in CALIBRATION_MAE.items()}
SPEC_PRESS_D0_PX = {k: v["press_d0"] for k, v in CALIBRATION_MAE.items()}
COLUMNS = ("interaction", "undeformed_px", "paper_params_px", "fitted_px", "fitted_mm", "used_for_fit")


@dataclass
class Validation:
    rows: list[dict]  # one per interaction: COLUMNS plus press_d0_px and the SPEC values
    summary: dict  # means (all, without twist_z), the other twist_z angle, what was simulated
    fitted_markers: dict[str, np.ndarray]  # kind -> (127, 2) simulated markers of our fit
    paper_markers: dict[str, np.ndarray]


def env_of(fixed: Mapping[str, float], params: Mapping[str, float]) -> dict:
    """Per-env twin parameters of a parameter set: `params` override `fixed` (env-level, so k_n and
    k_n_ref cannot both survive)."""
    return {**to_env(fixed), **to_env(params), "vessel": False}


def validate(targets: Sequence[Target], simulate: Simulator, template_px: np.ndarray, rest_d0_px: np.ndarray,
             fixed: Mapping[str, float], paper: Mapping[str, float], fitted: Mapping[str, float],
             fit: Sequence[str], geometry: str = "photo", twist_z_angle: str = "reference",
             twin_rest_px: np.ndarray | None = None) -> Validation:
    envs = {"paper": env_of(fixed, paper), "fitted": env_of(fixed, fitted)}
    requests, keys = [], []
    for t in targets:
        for which, env in envs.items():
            requests.append((t.kind, {**env, **target_geometry(t, geometry, twist_z_angle)}))
            keys.append((which, t.kind))
    other = "filename" if twist_z_angle == "reference" else "reference"
    twist_z = next((t for t in targets if t.kind == "twist_z"), None)
    if twist_z is not None:
        requests.append(("twist_z", {**envs["fitted"], **target_geometry(twist_z, geometry, other)}))
        keys.append(("fitted_other_angle", "twist_z"))
    markers, failed = simulate(requests)
    if failed.any():
        bad = [keys[i] for i in np.flatnonzero(failed)]
        raise ValueError(f"validation: the twin diverged for {bad}; check the fitted parameters")
    sim = {key: m for key, m in zip(keys, markers)}
    photo = {t.kind: t.markers for t in targets}
    undeformed, d0 = undeformed_mae(template_px, targets), undeformed_mae(rest_d0_px, targets)
    twin_rest = undeformed_mae(twin_rest_px, targets) if twin_rest_px is not None else {}
    rows = []
    for t in targets:
        fitted_px = marker_mae_px(sim["fitted", t.kind], photo[t.kind])
        rows.append({"interaction": t.kind, "undeformed_px": undeformed[t.kind],
                     "paper_params_px": marker_mae_px(sim["paper", t.kind], photo[t.kind]),
                     "fitted_px": fitted_px, "fitted_mm": fitted_px * MM_PER_PX,
                     "used_for_fit": t.kind in fit,
                     "press_d0_px": d0[t.kind], "twin_rest_px": twin_rest.get(t.kind),
                     "spec_twin_px": SPEC_TWIN_PX.get(t.kind),
                     "spec_undeformed_px": SPEC_UNDEFORMED_PX.get(t.kind),
                     "spec_press_d0_px": SPEC_PRESS_D0_PX.get(t.kind)})
    summary = {"mean": mean_rows(rows), "mean_without_twist_z": mean_rows(rows, skip="twist_z"),
               "twist_z_angle": twist_z_angle, "geometry": geometry,
               "paper_env": envs["paper"], "fitted_env": envs["fitted"]}
    if twist_z is not None:
        other_px = marker_mae_px(sim["fitted_other_angle", "twist_z"], photo["twist_z"])
        summary["twist_z_other_angle"] = {
            "angle_source": other, "fitted_px": other_px,
            "angle_deg": requests[-1][1].get("angle_deg", 30.0)}
    return Validation(rows, summary, {k: m for (w, k), m in sim.items() if w == "fitted"},
                      {k: m for (w, k), m in sim.items() if w == "paper"})


def mean_rows(rows: Sequence[dict], skip: str | None = None) -> dict:
    """Column means over the interactions (optionally without one), px and the fitted mm."""
    use = [r for r in rows if r["interaction"] != skip]
    out = {k: float(np.mean([r[k] for r in use])) for k in ("undeformed_px", "press_d0_px", "paper_params_px",
                                                           "fitted_px")}
    rest = [r.get("twin_rest_px") for r in use]
    out["twin_rest_px"] = float(np.mean(rest)) if all(v is not None for v in rest) else None
    out["fitted_mm"] = out["fitted_px"] * MM_PER_PX
    out["n"] = len(use)
    for k, ref in (("spec_twin_px", SPEC_TWIN_PX), ("spec_undeformed_px", SPEC_UNDEFORMED_PX)):
        vals = [ref.get(r["interaction"]) for r in use]
        out[k] = float(np.mean(vals)) if all(v is not None for v in vals) else None
    return out
