"""Hydra entry point: calibration and map threshold cross-fitted between the two real sets.

    python -m palpation.apps.recipe_crossfit runs_root=results/recipe out_dir=results/recipe/report
From the recipe ablation's stored runs (no retraining; the rows of palpation.apps.recipe_report): a Sim-trained
model is deployed on one real set and calibrated on the *same model's* scores on the other (A-to-B on its
A-to-C scores, A-to-C on its A-to-B scores; both configurations are one training, checked per seed). Per row and
calibration (`calibrations`): ECE, share positive at 0.5, Brier score, AP, and d̄ of the vessel map at a threshold
chosen on data other than the test set. Writes recipe_calibration_crossfit.csv/.json and reliability_crossfit.png/.pdf.
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf
from scipy.special import expit
from sklearn.metrics import average_precision_score

from palpation.apps.recipe_report import FULL, ROW_RANGES, load_group, maps_config, row_groups
from palpation.apps.vessel_maps import silicone_layout, source_for
from palpation.config_check import app_main
from palpation.config_ranges import Choice, DictOf, ListOf
from palpation.figures.recipe import reliability_figure
from palpation.io import atomic_path, save_figure, save_json
from palpation.mapping.pipeline import TEST_DATASET, MapSettings, config_maps
from palpation.mapping.stats import map_stats
from palpation.metrics.calibration import (Calibrator, brier, cross_fit, ece, fit_calibrator, positive_share,
                                         reliability)
from palpation.report.tables import crossfit_table

log = logging.getLogger(__name__)
CALIBRATIONS = ("stored", "cross_real", "cross_real_shift", "in_sample")
RANGES = {**ROW_RANGES, "calibrations": ListOf(Choice(*CALIBRATIONS), unique=True),  # before any work
          "partners": DictOf(Choice(*TEST_DATASET, null=True))}


def stored_calibrator(metrics: dict) -> Calibrator:
    """The calibration a run applied to the scores it wrote (identity where it calibrated nothing)."""
    cal = metrics.get("calibration")
    return Calibrator(**cal) if cal else Calibrator()


def to_raw(probs, cal: Calibrator) -> np.ndarray:
    """The model's own scores back from the written ones: inverts sigmoid(scale · logit + shift). No EPS clip
    (a written float32 score far below 1e-7 still carries its rank); only exact 0 and 1 are held off."""
    p = np.asarray(probs, np.float64)
    if cal.method == "none":
        return p
    p = np.clip(p, np.finfo(np.float64).tiny, np.nextafter(1.0, 0.0))
    return expit((np.log(p) - np.log1p(-p) - cal.shift) / cal.scale)


def same_model(a: dict, b: dict) -> bool:
    """Two runs of one seed scored by one trained model: the same epoch history and stored calibration."""
    return a.get("history") == b.get("history") and a.get("calibration") == b.get("calibration")


def map_at(res, threshold: float) -> dict:
    """d̄ (mm), exact-pixel recall and predicted pixels of a configuration's map stack at a threshold on the
    stored scores' scale (d̄ alone rewards a high threshold: few pixels, all near the vessel)."""
    st = map_stats(res.stack.score, res.stack.visited, res.stack.truth, threshold, 0)
    return {"d_bar_mm": st["distance_mm"]["mean"], "map_recall": st["recall"], "map_pred_px": st["distance_mm"]["n"]}


def _partner_threshold(own: Calibrator, p_res, p_own: Calibrator) -> float:
    """The partner map's SPEC §12 threshold, carried to this run's stored scale through the raw score."""
    return float(own.apply(to_raw(np.array([p_res.op.threshold]), p_own))[0])


def seed_rows(config, run, res, partner, p_run, p_res, calibrations) -> list[dict]:
    """One seed's figures per calibration. Only the partner's scores and map fit `cross_real(_shift)`."""
    s, own = run["scores_arrays"], stored_calibrator(run["metrics"])
    raw, labels = to_raw(s["probs"], own), s["labels"]
    val_name = f"{run['metrics']['train_on']}_val"
    out = []
    for name in calibrations:
        cal, thr, map_from = None, res.op.threshold, "test map (SPEC §12, quirk 18)"
        if name == "stored":  # a run trained with calibration=cross_real names its partner
            fitted_on = run["metrics"].get("calibration_fitted_on", val_name) if own.method != "none" else "none"
        elif name == "in_sample":  # a bound, not a result: Platt fitted on the test set itself
            cal, fitted_on = fit_calibrator(raw, labels, "platt"), f"{TEST_DATASET[config]} (itself: bound)"
        elif partner is None:  # no other real set: the stored (training domain's val) calibration and its 0.5
            fitted_on = val_name if own.method != "none" else "none"
            thr, map_from = 0.5, "0.5 of the stored scores"
        elif name == "cross_real_shift":  # the stored slope kept, only the intercept refitted on the partner
            ps, p_own = p_run["scores_arrays"], stored_calibrator(p_run["metrics"])
            if p_own != own:
                raise ValueError(f"{config}: cross_real_shift needs the partner {partner} written with the same "
                                 "calibration (the same models); drop it from calibrations")
            b = cross_fit({partner: (ps["probs"], ps["labels"])}, {config: partner}, "shift")[config].shift
            cal = Calibrator("platt", own.scale, own.shift + b, own.n_fit) if own.method != "none" else \
                Calibrator("shift", 1.0, b)
            slope = val_name if own.method != "none" else "1"
            fitted_on = f"{TEST_DATASET[partner]} ({partner} scores; slope {slope})"
            thr, map_from = _partner_threshold(own, p_res, p_own), f"{TEST_DATASET[partner]} map (SPEC §12 rule)"
        else:
            ps, p_own = p_run["scores_arrays"], stored_calibrator(p_run["metrics"])
            cal = cross_fit({partner: (to_raw(ps["probs"], p_own), ps["labels"])}, {config: partner})[config]
            fitted_on = f"{TEST_DATASET[partner]} ({partner} scores)"
            thr = _partner_threshold(own, p_res, p_own)
            map_from = f"{TEST_DATASET[partner]} map (SPEC §12 rule)"
        probs = s["probs"] if cal is None else cal.apply(raw)
        # calibrated >= 0.5  <=>  raw >= sigmoid(-shift / scale): that point on the stored scale (maps: max per pixel)
        t05 = 0.5 if cal is None else float(own.apply(np.array([expit(-cal.shift / cal.scale)]))[0])
        out.append({"calibration": name, "fitted_on": fitted_on, "map_threshold_from": map_from,
                    "ece": ece(probs, labels), "pos_share_05": positive_share(probs), "brier": brier(probs, labels),
                    "ap": float(average_precision_score(labels, probs)), **map_at(res, thr),
                    **{f"{k.removesuffix('_mm')}_05{'_mm' if k.endswith('_mm') else ''}": v
                       for k, v in map_at(res, t05).items() if k != "map_pred_px"}, "probs": probs})
    return out


def row_figures(config, recipe, switch, seeds: list[list[dict]]) -> list[dict]:
    """Means over seeds per calibration (sample std of ECE)."""
    rows = []
    for i, first in enumerate(seeds[0]):
        per = [s[i] for s in seeds]
        mean = lambda k: float(np.nanmean([p[k] for p in per])) if any(p[k] == p[k] for p in per) else float("nan")
        rows.append({"config": config, "recipe": recipe, "switch_off": switch, "calibration": first["calibration"],
                     "fitted_on": first["fitted_on"], "map_threshold_from": first["map_threshold_from"],
                     "seeds": len(per), "ece": mean("ece"),
                     "ece_std": float(np.std([p["ece"] for p in per], ddof=1)) if len(per) > 1 else float("nan"),
                     **{k: mean(k) for k in ("pos_share_05", "brier", "ap", "d_bar_mm", "map_recall", "map_pred_px",
                                              "d_bar_05_mm", "map_recall_05")},
                     "d_bar_05_seeds": int(sum(p["d_bar_05_mm"] == p["d_bar_05_mm"] for p in per))})  # with a pixel
    return rows


def _used_bins(probs, labels) -> dict:
    """The figure's reliability bins (pooled over seeds), the non-empty ones: lower edge, mean score, share, count."""
    r = reliability(probs, labels)
    used = r["count"] > 0
    return {"lower_edge": r["edges"][:-1][used].tolist(), "confidence": r["confidence"][used].tolist(),
            "frequency": r["frequency"][used].tolist(), "count": r["count"][used].tolist()}


def run(cfg: DictConfig) -> dict:
    c = OmegaConf.to_container(cfg, resolve=True)
    c.pop("hydra", None)
    out = Path(c["out_dir"])
    bad = [k for k in c["calibrations"] if k not in CALIBRATIONS]
    if bad:
        raise ValueError(f"unknown calibration(s) {bad} in calibrations; use {list(CALIBRATIONS)}")
    for config in c["experiments"]:
        p = c["partners"].get(config, "missing")
        if p == "missing" or (p is not None and (p not in c["experiments"] or p == config)):
            raise ValueError(f"partners.{config}: {p!r}; name another configuration of experiments trained by the "
                             "same models, or null where there is no other real set")
    maps = maps_config(c)
    settings = MapSettings(max_grid_px=int(maps["max_grid_px"]), sim_max_maps=maps["sim"]["max_maps"],
                           sim_vessel_only=bool(maps["sim"]["vessel_only"]), **maps["threshold"])
    layout = silicone_layout(maps)[0] if any(TEST_DATASET[k] == "silicone" for k in c["experiments"]) else None
    cache = {}

    def loaded(config, recipe, switch):  # runs with their scores and maps, built once per row
        key = (config, recipe, switch)
        if key not in cache:
            runs, _ = load_group({**c, "partial": False}, config, recipe, switch)
            for r in runs:
                source, r["scores_arrays"] = source_for(maps, config, r, layout)
                r["maps"] = config_maps(config, source, **r["scores_arrays"], settings=settings)
            cache[key] = runs
        return cache[key]

    rows, checks, panels = [], {}, {}
    for config in c["experiments"]:
        partner = c["partners"][config]
        for recipe, switch in row_groups(c, config):
            if partner is not None and (recipe, switch) not in row_groups(c, partner):
                raise ValueError(f"{config} {recipe} -{switch}: its partner {partner} has no such row; add {partner} "
                                 "to switch_experiments or set partners.{config}=null")
            runs = loaded(config, recipe, switch)
            p_runs = loaded(partner, recipe, switch) if partner else [None] * len(runs)
            if partner:
                same = [same_model(r["metrics"], p["metrics"]) for r, p in zip(runs, p_runs)]
                checks[f"{config}/{recipe}/{switch}"] = same
                if not all(same):  # still cross-fitted, on the same seed's other run: said in the json and log
                    log.warning("%s %s -%s: seeds %s are separate trainings from %s's", config, recipe, switch,
                                [r["seed"] for r, ok in zip(runs, same) if not ok], partner)
            seeds = [seed_rows(config, r, r["maps"], partner, p, p and p["maps"], c["calibrations"])
                     for r, p in zip(runs, p_runs)]
            rows += row_figures(config, recipe, switch, seeds)
            if (recipe, switch) == ("robust", FULL):  # the figure: the full robust recipe per test set
                labels = np.concatenate([r["scores_arrays"]["labels"] for r in runs])
                panels[f"{config} robust"] = {
                    f"{row['calibration']} ({row['fitted_on']})": (np.concatenate([q[i]["probs"] for q in seeds]), labels)
                    for i, row in enumerate(seeds[0])}
            for r in rows[-len(c["calibrations"]):]:
                log.info("%s %s -%s %s (%s): ECE %.3f, positive at 0.5 %.1f %%, Brier %.4f, d-bar %.2f mm", config,
                         recipe, switch, r["calibration"], r["fitted_on"], r["ece"], 100 * r["pos_share_05"],
                         r["brier"], r["d_bar_mm"])
    table = crossfit_table(rows)
    with atomic_path(out / "recipe_calibration_crossfit.csv") as tmp:
        table.to_csv(tmp, index=False, float_format="%.6g")
    bins = {panel: {curve: _used_bins(*pl) for curve, pl in curves.items()} for panel, curves in panels.items()}
    save_json(out / "recipe_calibration_crossfit.json", {"rows": rows, "same_model": checks, "reliability": bins,
                                                         "partners": c["partners"], "seeds": c["seeds"]})
    save_figure(reliability_figure(panels, "Reliability of the test scores: stored vs cross-fitted calibration"),
                out / "reliability_crossfit")
    return {"rows": rows, "same_model": checks}


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="recipe_crossfit")
@app_main("recipe_crossfit", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
