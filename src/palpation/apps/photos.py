"""Hydra entry point: detect and order the flat-tip photos; write the measured set, overlay and summary.

Outputs (under `out.dir`): measured_photos.npz/.json (docs/measured_format.md), markers_overlay.png/.pdf
and photo_summary.json/.csv (per-photo counts, spacing, displacement vs press d=0 and the
undeformed-sensor baseline MAE, next to the SPEC §13.2/§15.8 values).
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
import pandas as pd
from omegaconf import DictConfig, OmegaConf

from palpation.config_check import app_main
from palpation.config_ranges import Int, Num
from palpation.io import save_json, save_text
from palpation.markers.detect import RatioDetector
from palpation.markers.lattice import N_MARKERS
from palpation.markers.manifest import read_manifest
from palpation.markers.photoset import list_photos, measure_photos, reference_pipeline_baselines
from palpation.markers.template import template_from_photo
from palpation.measured import save_measured_set

log = logging.getLogger(__name__)
# checked before any work (config_ranges); detector sizes in pixels of the 1920x1080 photo
RANGES = {"max_missing": Int(ge=0, le=N_MARKERS), "detector.background_px": Int(ge=3, odd=True),
          "detector.ratio_max": Num(gt=0, le=1), "detector.background_min": Num(ge=0, le=255),
          "detector.opening_px": Int(ge=1), "detector.area_min_px2": Num(ge=0), "detector.area_max_px2": Num(gt=0),
          "detector.aspect_max": Num(ge=1), "detector.fill_min": Num(ge=0, le=1), "detector.dummy_factor": Num(gt=0),
          "detector.rescue_aspect_max": Num(ge=1), "detector.rescue_fill_min": Num(ge=0, le=1),
          "detector.glint_min": Num(ge=0, le=255), "detector.glint_close_px": Int(ge=1)}

# SPEC §13.2 (median / max displacement vs press d=0, px) and §15.8 (undeformed baselines, px)
SPEC_VALUES = {
    "press_d4": {"disp_median_px": 14.3, "disp_max_px": 19.8, "baseline_mae_template_px": 13.95,
                 "baseline_mae_rest_photo_px": 13.81, "median_nn_spacing_px": 51.2},
    "twist_z_d4_a90": {"disp_median_px": 16.5, "disp_max_px": 22.2, "baseline_mae_template_px": 15.40,
                       "baseline_mae_rest_photo_px": 15.29, "median_nn_spacing_px": 51.4},
    "twist_x_d2_a20": {"disp_median_px": 17.0, "disp_max_px": 33.3, "baseline_mae_template_px": 16.27,
                       "baseline_mae_rest_photo_px": 16.74, "median_nn_spacing_px": 50.3},
    "slide_d3": {"disp_median_px": 13.6, "disp_max_px": 29.9, "baseline_mae_template_px": 14.15,
                 "baseline_mae_rest_photo_px": 14.70, "median_nn_spacing_px": 50.8},
    "sensor_default_state": {"disp_median_px": 1.37, "median_nn_spacing_px": 53.3},
    "press_d0": {"median_nn_spacing_px": 53.5},
}
CALIBRATION_TARGETS = ("press_d4", "twist_z_d4_a90", "twist_x_d2_a20", "slide_d3")


def run(cfg: DictConfig) -> dict:
    params = RatioDetector(**OmegaConf.to_container(cfg.detector, resolve=True))
    photos_dir = Path(cfg.photos_dir)
    manifest = cfg.get("photos_manifest")
    # any photo set with a manifest (file, kind, depth, angle); else the paper's file names
    photos = read_manifest(manifest, photos_dir) if manifest else list_photos(photos_dir)
    template = template_from_photo(photos_dir / cfg.template_photo, params)
    mset, rows = measure_photos(photos, template, cfg.rest_photo, params, blob_counts=cfg.blob_counts,
                                max_missing=int(cfg.get("max_missing", 0)))
    # the reference's own pipeline (blob detectors + its hand-placed markers), as a check on its photos
    replica = reference_pipeline_baselines(photos, cfg.rest_photo) if cfg.blob_counts and not manifest else {}
    mset.meta.update(
        camera={"model": "equidistant fisheye", "f_px": 380.0, "cx_px": 1040.0, "cy_px": 584.0,
                "image_size_px": [1920, 1080], "circle_radius_px": 380.0},
        detector={"kind": "ratio", **params.__dict__},
        template_source=cfg.template_photo, rest_source=cfg.rest_photo, photos_dir=str(photos_dir),
        photos_manifest=str(manifest) if manifest else None)
    for row in rows:
        row.update({f"spec_{k}": v for k, v in SPEC_VALUES.get(row["name"], {}).items()})
        row.update({f"refpipe_{k}": v for k, v in replica.get(row["name"], {}).items()})
    by_name = {r["name"]: r for r in rows}
    targets = [by_name[n] for n in CALIBRATION_TARGETS if n in by_name]
    summary = {"photos": rows,
               "mean_baseline_mae_template_px": _mean(targets, "baseline_mae_template_px"),
               "mean_baseline_mae_rest_photo_px": _mean(targets, "baseline_mae_rest_photo_px"),
               "spec_mean_baseline_mae_template_px": 14.94,
               "spec_mean_baseline_mae_rest_photo_px": 15.14,
               "refpipe_mean_baseline_mae_template_px": _mean(targets, "refpipe_baseline_mae_template_px"),
               "refpipe_mean_baseline_mae_rest_photo_px": _mean(targets, "refpipe_baseline_mae_rest_photo_px")}

    out = Path(cfg.out.summary)
    save_measured_set(cfg.out.measured, mset)
    save_json(out.with_name(out.name + ".json"), summary)
    save_text(out.with_name(out.name + ".csv"), pd.DataFrame(rows).to_csv(index=False, float_format="%.4f"))
    if cfg.figure:
        from palpation.figures.markers_overlay import plot_markers_overlay

        plot_markers_overlay(mset, photos_dir, cfg.out.figure)
    for row in rows:
        log.info("%-22s %3d markers (%3d candidates), spacing %.2f px, |d| median %.2f max %.2f px, "
                 "baseline MAE template %.2f / press-d0 %.2f px", row["name"], row["n_markers"],
                 row["n_candidates"], row["median_nn_spacing_px"], row["disp_median_px"],
                 row["disp_max_px"], row["baseline_mae_template_px"], row["baseline_mae_rest_photo_px"])
    for name, base in replica.items():
        log.info("reference pipeline (blob + hand markers) %-16s baseline MAE template %.2f / press-d0 "
                 "%.2f px", name, base["baseline_mae_template_px"], base["baseline_mae_rest_photo_px"])
    if cfg.track:
        _track(cfg, rows, summary)
    return summary


def _mean(rows: list[dict], key: str) -> float | None:
    values = [r[key] for r in rows if key in r]
    return float(sum(values) / len(values)) if values else None


def _track(cfg: DictConfig, rows: list[dict], summary: dict) -> None:
    from palpation.tracking import log_metrics, start_run

    metrics = {f"{r['name']}/{k}": r[k] for r in rows
               for k in ("n_markers", "disp_median_px", "disp_max_px", "baseline_mae_template_px")}
    metrics["photos/mean_baseline_mae_template_px"] = summary["mean_baseline_mae_template_px"] or 0.0
    with start_run("photos", params=OmegaConf.to_container(cfg, resolve=True)):
        log_metrics(metrics)


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="photos")
@app_main("photos", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
