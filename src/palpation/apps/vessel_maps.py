"""Hydra entry point: vessel maps, operating points, Table 4 lower half and Fig. 7 (SPEC §12).

    python -m palpation.apps.vessel_maps runs.root=results/train out_dir=results/maps
    python -m palpation.apps.vessel_maps configs=[A-to-B] scores.A-to-B=run/scores.npz
Writes into out_dir: table4_maps.{csv,md}, table4_maps_photo.csv, vessel_maps.json, maps_<config>.npz,
fig7_confusion_maps.{png,pdf}, fig7_threshold_selection.{png,pdf}, <config>_confusion[_big].png and
silicone_pose_check.json.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import hydra
import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf

from palpation import tracking
from palpation.figures import maps as figures
from palpation.config_check import app_main
from palpation.io import atomic_path, save_json, save_npz, save_text
from palpation.mapping import config as maps_config  # noqa: F401 (registers the schema base_vessel_maps)
from palpation.mapping.pipeline import TEST_DATASET, MapSettings, config_maps
from palpation.mapping.silicone_check import pose_check
from palpation.mapping.silicone_poses import SweepLayout, direction_evidence, estimate_mirror
from palpation.mapping.sources import meat_source, sim_source, silicone_source
from palpation.metrics.aggregate import best_of_five
from palpation.metrics.scores import load_scores
from palpation.readers import read_json, read_npz
from palpation.report.runs import run_dir
from palpation.report.tables import table4_maps, table4_maps_markdown, table4_maps_row

log = logging.getLogger(__name__)


def pick_run(c: dict, config: str) -> dict:
    """The configuration's scores: an explicit path, or the best-of-five run under runs.root."""
    explicit = (c.get("scores") or {}).get(config)
    if explicit:
        return {"scores": str(explicit), "dir": str(Path(explicit).parent), "seed": None}
    runs, missing = [], []
    for seed in c["runs"]["seeds"]:
        d = run_dir(c["runs"]["root"], config, c["clip_len"], seed)
        if not (d / "metrics.json").exists():
            missing.append(str(d / "metrics.json"))
            continue
        test = read_json(d / "metrics.json", "rerun the train rule for this run", keys=("test",))["test"]
        if not isinstance(test, dict) or not {"ap", "auroc"} <= test.keys():
            raise ValueError(f"{d / 'metrics.json'}: `test` lacks ap/auroc; rerun the train rule for this run")
        runs.append({"seed": seed, "ap": test["ap"], "auroc": test["auroc"], "dir": str(d)})
    if not runs:
        raise FileNotFoundError(f"{config}: no training run found ({missing[:2]}); train it first or pass "
                                f"scores.{config}=<path to scores.npz>")
    best = best_of_five(runs)
    return {**best, "scores": str(Path(best["dir"]) / "scores.npz")}


def silicone_layout(c: dict) -> tuple[SweepLayout, dict]:
    """The sweep layout of the config; a null mirror_sum is measured from the annotation dots."""
    fields = {k: v for k, v in c["silicone_layout"].items() if v is not None}
    arrays = read_npz(c["data"]["silicone"], ("markers", "labels", "dots", "dot_counts", "line_angle_deg"),
                      "rerun the silicone_set rule", "Silicone set", finite=("markers", "line_angle_deg"))
    evidence = {"directions": direction_evidence(arrays["markers"], arrays["dots"], arrays["dot_counts"],
                                                 arrays["line_angle_deg"])}
    if "mirror_sum" not in fields:
        mirror = estimate_mirror(arrays["dots"], arrays["dot_counts"], arrays["line_angle_deg"])
        fields["mirror_sum"], evidence["mirror"] = mirror["m"], mirror
    layout = SweepLayout(**fields)
    evidence["check"] = pose_check(arrays["markers"], arrays["labels"], arrays["dots"], arrays["dot_counts"], layout)
    return layout, evidence


def source_for(c: dict, config: str, run: dict, layout: SweepLayout | None):
    """(MapSource, {probs, labels, sequence, frame}) of one configuration."""
    dataset = TEST_DATASET[config]
    if dataset == "silicone":
        return silicone_source(c["data"]["silicone"], layout), vars(load_scores(run["scores"]))
    if dataset == "meat":
        return meat_source(c["data"]["meat"]), vars(load_scores(run["scores"]))
    if c["sim"]["source"] == "slide":
        from palpation.mapping.rescore import score_dense

        dense = score_dense(Path(run["dir"]) / "checkpoint.pt", c["sim"]["slide_manifest"], "all",
                            c["sim"]["batch_size"], c["device"], progress=bool(c["progress"]))
        source = sim_source(c["sim"]["slide_manifest"], "all")
        return source, {k: dense[k] for k in ("probs", "labels", "sequence", "frame")}
    if c["sim"]["source"] != "test":
        raise ValueError(f"sim.source must be 'test' or 'slide', got {c['sim']['source']!r}")
    return sim_source(c["data"]["sim"], "test"), vars(load_scores(run["scores"]))


def save_csv(df: pd.DataFrame, path: Path) -> None:
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False, float_format="%.6g")


def run(cfg: DictConfig) -> dict:
    c = OmegaConf.to_container(cfg, resolve=True)
    c.pop("hydra", None)
    out = Path(c["out_dir"])
    unknown = [k for k in c["configs"] if k not in TEST_DATASET]
    if unknown:
        raise ValueError(f"unknown configuration(s) {unknown}; use {sorted(TEST_DATASET)}")
    unknown = [f"scores.{k}" for k in c["scores"] if k not in TEST_DATASET]
    if unknown:
        raise ValueError(f"unknown config key(s) {unknown} in conf/vessel_maps.yaml or the overrides; scores "
                         f"are given per configuration: {sorted(TEST_DATASET)}")
    settings = MapSettings(max_grid_px=int(c["max_grid_px"]),
                           sim_max_maps=c["sim"]["max_maps"], sim_vessel_only=bool(c["sim"]["vessel_only"]),
                           **c["threshold"])
    layout, evidence = None, None
    if any(TEST_DATASET[k] == "silicone" for k in c["configs"]):
        layout, evidence = silicone_layout(c)
        save_json(out / "silicone_pose_check.json", evidence)
        log.info("Silicone poses: mirror sum %.3f (step %.3f mm); video-vs-photo IoU %.4f, dots to photo %.2f mm",
                 layout.mirror_sum, layout.step_mm, evidence["check"]["iou_video_photo"],
                 evidence["check"]["dots_to_photo_mm"]["mean"])
    rows, photo_rows, panels, curves, summary = [], [], [], [], {}
    for config in c["configs"]:
        picked = pick_run(c, config)
        source, scores = source_for(c, config, picked, layout)
        res = config_maps(config, source, **scores, settings=settings)
        rows.append(table4_maps_row(config, res.op, res.stats))
        pred = res.stack.visited & (res.stack.score >= res.op.threshold)
        image = figures.confusion_mosaic(res.stack.score, res.stack.visited, res.stack.truth, res.op.threshold)
        figures.save_rgb(image, out / f"{config}_confusion.png")
        figures.save_rgb(image, out / f"{config}_confusion_big.png", figures.BIG)
        panels.append((f"{config} ({res.dataset}, video truth): thr {res.op.threshold:.4f}, "
                       f"d̄ {res.stats['d_bar_mm']:.2f} mm", image))
        curves.append((config, res.curve, res.op))
        arrays = {"score": res.stack.score, "visited": res.stack.visited, "truth": res.stack.truth, "pred": pred}
        entry = {"run": picked, "dataset": res.dataset, "n_samples": res.n_samples, "maps": res.stack.names,
                 "grid": res.stack.grid.to_dict(), "dropped_samples": res.stack.dropped,
                 "operating_point": res.op.to_dict(), "stats": res.stats, "meta": res.meta}
        if res.photo is not None:
            p = res.photo
            photo_rows.append(table4_maps_row(f"{config}/photo", p["op"], p["stats"]))
            arrays["photo_truth"] = p["truth"]
            photo_image = figures.confusion_mosaic(res.stack.score, res.stack.visited, p["truth"], p["op"].threshold)
            figures.save_rgb(photo_image, out / f"{config}_photo_confusion.png")
            figures.save_rgb(photo_image, out / f"{config}_photo_confusion_big.png", figures.BIG)
            entry["photo"] = {"operating_point": p["op"].to_dict(), "stats": p["stats"],
                              "iou_video_photo": p["iou_video_photo"]}
        save_npz(out / f"maps_{config}.npz", **arrays)
        summary[config] = entry
        log.info("%s: thr %.4f (%s) TP %d FP %d FN %d d-bar %.3f mm", config, res.op.threshold, res.op.rule,
                 res.stats["r0"]["tp"], res.stats["r0"]["fp"], res.stats["r0"]["fn"], res.stats["d_bar_mm"])
    table = table4_maps(rows)
    photo = table4_maps(photo_rows)
    save_csv(table, out / "table4_maps.csv")
    save_csv(photo, out / "table4_maps_photo.csv")
    notes = _notes(c, layout, evidence)
    save_text(out / "table4_maps.md", table4_maps_markdown(table, c["profile"], notes, photo))
    figures.fig7(panels, out / "fig7_confusion_maps", f"Vessel maps ({c['profile']} profile)")
    figures.threshold_figure(curves, out / "fig7_threshold_selection")
    save_json(out / "vessel_maps.json", {"profile": c["profile"], "configs": summary,
                                         "silicone_layout": dataclasses.asdict(layout) if layout else None})
    if c.get("track"):
        _track(c, table, out)
    return {"table": table.to_dict("records"), "photo": photo.to_dict("records"), "configs": summary}


def _notes(c: dict, layout: SweepLayout | None, evidence: dict | None) -> list[str]:
    notes = ["Statistics use exact pixels; the 3 mm tolerance only chooses the threshold (SPEC §12).",
             f"Sim maps: {c['sim']['source']} windows, up to {c['sim']['max_maps']} vessel-present slides "
             "(the paper: one dedicated slide); Meat: 10 trial maps, counts summed.",
             "Meat poses: straight slide along -y at x = 0, timed from the kinematic labels (mapping/meat_poses.py)."]
    if layout is not None and evidence is not None:
        ch = evidence["check"]
        notes.append(f"Silicone poses reconstructed (no robot poses in the data): step {layout.step_mm:.2f} mm "
                     f"(mirror sum {layout.mirror_sum:.2f}), paths {layout.path_spacing_mm:g} mm apart about x = "
                     f"{layout.centre_x_mm:g}, y centre {layout.centre_y_mm:g}; check: video-vs-photo truth IoU "
                     f"{ch['iou_video_photo']:.4f} (paper 0.2934), annotation dots {ch['dots_to_photo_mm']['mean']:.2f} "
                     f"mm from the photo polygons (mean).")
    return notes


def _track(c: dict, table: pd.DataFrame, out: Path) -> None:
    params = {k: c[k] for k in ("profile", "clip_len", "configs", "sim", "silicone_layout", "threshold")}
    with tracking.start_run("vessel_maps", params, config=c['profile']):
        for row in table.to_dict("records"):
            tracking.log_metrics({f"{row['config']}/{k}": row[k] for k in ("threshold", "mcc", "f1", "precision",
                                                                             "recall", "ap", "d_bar_mm")
                                  if row[k] == row[k]})
        for name in ("table4_maps.csv", "table4_maps.md", "vessel_maps.json"):
            tracking.log_artifact(out / name)
        for stem in ("fig7_confusion_maps", "fig7_threshold_selection"):
            tracking.log_figure(out / stem)


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="vessel_maps")
@app_main("vessel_maps")
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
