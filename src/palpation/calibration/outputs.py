"""Calibration outputs: the fitted twin as a Hydra config other stages load, and the MAE table.

`<out>/twin_fit/fitted.yaml` is a config-group option in package `twin`: any app composing a `twin`
config picks the fit up with two overrides (no copy step),
    hydra.searchpath=[file://<out>] +twin_fit=fitted
which workflow/rules/calibrate.smk provides as `TWIN_FIT_ARGS` (with `TWIN_FIT` as the rule input).
It holds the searched values and the values the search held fixed, in the twin's physical units.
`<out>/fitted_params.yaml` is the readable record (registry names and units, objective, trial).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import yaml

from palpation.calibration.params import REGISTRY, twin_overrides
from palpation.calibration.validate import COLUMNS, Validation
from palpation.io import csv_text, save_json, save_text

TWIN_FIT_GROUP = "twin_fit"
TWIN_FIT_NAME = "fitted"


def twin_fit_path(out_dir: str | Path) -> Path:
    return Path(out_dir) / TWIN_FIT_GROUP / f"{TWIN_FIT_NAME}.yaml"


def twin_fit_overrides(out_dir: str | Path) -> list[str]:
    """The Hydra overrides that load the fit written under `out_dir` into `twin`."""
    return [f"hydra.searchpath=[file://{Path(out_dir)}]", f"+{TWIN_FIT_GROUP}={TWIN_FIT_NAME}"]


def write_fitted(out_dir: str | Path, fitted: Mapping[str, float], fixed: Mapping[str, float],
                 record: Mapping) -> tuple[Path, Path]:
    """Write the Hydra option and the readable record; returns both paths."""
    values = {**fixed, **fitted}
    head = ("# @package twin\n# Fitted by palpation.apps.calibrate (objective "
            f"{record.get('objective')}, study {record.get('study')}, trial {record.get('trial')}).\n"
            f"# Load with: {' '.join(twin_fit_overrides(out_dir))}\n")
    option = twin_fit_path(out_dir)
    save_text(option, head + yaml.safe_dump(twin_overrides(values), sort_keys=True))
    readable = {"fitted": {n: {"value": float(v), "unit": REGISTRY[n].unit} for n, v in fitted.items()},
                "fixed": {n: {"value": float(v), "unit": REGISTRY[n].unit} for n, v in fixed.items()},
                "twin": twin_overrides(values), **record}
    params = Path(out_dir) / "fitted_params.yaml"
    save_text(params, yaml.safe_dump(_plain(readable), sort_keys=False))
    return option, params


def table_csv(rows: list[dict]) -> str:
    return csv_text(rows, COLUMNS, digits=3)


def table_markdown(val: Validation, fitted: Mapping[str, float]) -> str:
    """The (a)/(b)/(c) table beside SPEC §15.8, with the means with and without twist_z."""
    f = lambda v: "–" if v is None else f"{v:.2f}"  # noqa: E731
    lines = ["| interaction | (a) undeformed: template | (a) press d=0 | twin at rest | (b) paper params "
             "| (c) fitted px (mm) | fit | SPEC twin | SPEC undeformed |", "|---" * 9 + "|"]
    for r in val.rows:
        lines.append(f"| {r['interaction']} | {f(r['undeformed_px'])} | {f(r['press_d0_px'])} | "
                     f"{f(r.get('twin_rest_px'))} | {f(r['paper_params_px'])} | "
                     f"{f(r['fitted_px'])} ({r['fitted_mm']:.2f}) | "
                     f"{'yes' if r['used_for_fit'] else 'held out'} | {f(r['spec_twin_px'])} | "
                     f"{f(r['spec_undeformed_px'])} |")
    for key, label in (("mean", "**mean**"), ("mean_without_twist_z", "mean w/o twist_z")):
        m = val.summary[key]
        lines.append(f"| {label} | {f(m['undeformed_px'])} | {f(m['press_d0_px'])} | "
                     f"{f(m.get('twin_rest_px'))} | "
                     f"{f(m['paper_params_px'])} | "
                     f"{f(m['fitted_px'])} ({m['fitted_mm']:.2f}) | | {f(m['spec_twin_px'])} | "
                     f"{f(m['spec_undeformed_px'])} |")
    other = val.summary.get("twist_z_other_angle")
    notes = ["", "MAE in px over the 127 markers (27.5 px/mm). (a) template = `sensor_default_state.png`, "
             "SPEC's undeformed rest markers; press d=0 = the rest photo; twin at rest = the template bound "
             "to the mesh's dome nodes, before any motion.",
             f"Fitted: {', '.join(f'{k} = {v:.6g}' for k, v in fitted.items())}; twist_z simulated at the "
             f"{val.summary['twist_z_angle']} angle (quirk 5)."]
    if other:
        notes.append(f"twist_z at the {other['angle_source']} angle ({other['angle_deg']:g} deg): "
                     f"{other['fitted_px']:.2f} px with the fit.")
    m = val.summary["mean"]
    line = (f"Mean over the photos: the fit is {margin(m['undeformed_px'], m['fitted_px'])} the undeformed "
            f"sensor (template, {m['undeformed_px']:.2f} px)")
    if m.get("twin_rest_px") is not None:
        line += (f" and {margin(m['twin_rest_px'], m['fitted_px'])} the twin at rest "
                 f"({m['twin_rest_px']:.2f} px)")
    notes.append(line + ".")
    return "\n".join(lines + notes) + "\n"


def margin(baseline: float, fitted: float) -> str:
    d = baseline - fitted
    return f"{abs(d):.2f} px {'better than' if d >= 0 else 'worse than'}"


def write_table(out_dir: str | Path, val: Validation, fitted: Mapping[str, float]) -> list[Path]:
    out = Path(out_dir)
    save_text(out / "calibration.csv", table_csv(val.rows))
    save_text(out / "calibration.md", table_markdown(val, fitted))
    save_json(out / "calibration.json", {"rows": val.rows, **_plain(val.summary)})
    return [out / "calibration.csv", out / "calibration.md", out / "calibration.json"]


def _plain(obj):
    """numpy scalars and tuples -> plain YAML/JSON types."""
    if isinstance(obj, Mapping):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if hasattr(obj, "item"):
        return obj.item()
    return obj
