"""Hydra entry point: the recipe ablation table, calibration and the seed-ensemble uncertainty.

    python -m palpation.apps.recipe_report runs_root=results/recipe out_dir=results/recipe/report
Reads <runs_root>/<recipe>/<switch_off>/<config>/L<clip_len>/seed<seed>/ (rule train_recipe) and writes
recipe_ablation.csv/.md, uncertainty.csv, reliability.png/.pdf (per test set, the full recipes),
uncertainty_maps.png/.pdf (beside Fig. 7), ensemble_<config>_<recipe>.npz and recipe_report.json.
The vessel maps use conf/vessel_maps.yaml's data, Silicone layout and threshold rule (its owner).
A missing run is an error; partial=true (a table from the runs a device session finished) leaves such rows
out whole and lists them (recipe_report.json `left_out`, the .md notes, the results page).
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from palpation import tracking
from palpation.apps.vessel_maps import silicone_layout, source_for
from palpation.config_check import app_main
from palpation.config_ranges import SEEDS, Choice, Int, ListOf, Num, Text
from palpation.figures.recipe import reliability_figure, uncertainty_figure
from palpation.io import atomic_path, save_figure, save_json, save_npz, save_text
from palpation.readers import read_json
from palpation.mapping.pipeline import TEST_DATASET, MapSettings, config_maps
from palpation.mapping.uncertainty import ensemble_map
from palpation.metrics.calibration import ece, positive_share
from palpation.metrics.ensemble import coverage_curve, ensemble
from palpation.model.recipe import SAME_TRAJECTORY, SWITCHES
from palpation.paths import REPO_ROOT
from palpation.report.paper import CONFIG_TITLES
from palpation.report.runs import recipe_root, run_dir
from palpation.report.tables import recipe_ablation, recipe_ablation_markdown, uncertainty_table

log = logging.getLogger(__name__)
FULL = "none"  # switch_off of a full recipe
CONFIGS = ListOf(Choice(*TEST_DATASET), unique=True)
# the rows' settings, read alike by recipe_crossfit; checked before any work (config_ranges)
ROW_RANGES = {"experiments": CONFIGS, "recipes": ListOf(Text(), unique=True),
              "switches": ListOf(Choice(*SWITCHES), 0, unique=True),
              "switch_experiments": ListOf(Choice(*TEST_DATASET), 0, unique=True, null=True), "seeds": SEEDS,
              "clip_len": Int(ge=1)}
RANGES = {**ROW_RANGES, "threshold": Num(gt=0, lt=1)}


def maps_config(c: dict) -> dict:
    """conf/vessel_maps.yaml (the owner of the map settings), with this app's data paths."""
    maps = OmegaConf.load(REPO_ROOT / "conf" / "vessel_maps.yaml")
    for key in ("defaults", "hydra"):
        maps.pop(key, None)
    maps = OmegaConf.to_container(maps, resolve=True)
    maps["data"] = dict(c["data"])
    maps["sim"]["source"] = "test"  # the test split's windows: no dense rescoring per seed
    return maps


def load_group(c: dict, config: str, recipe: str, switch: str) -> tuple[list[dict], list[int]]:
    """The finished runs of one row and the seeds whose run is missing. Missing runs raise unless
    `partial` is on (a table from the runs a device session finished; the row is then left out whole)."""
    runs, missing = [], []
    for seed in c["seeds"]:
        d = run_dir(recipe_root(c["runs_root"], recipe, switch), config, c["clip_len"], seed)
        if not (d / "metrics.json").exists():
            missing.append(seed)
            continue
        fix = "rerun the train_recipe rule for this run"
        runs.append({"seed": seed, "dir": str(d), "scores": str(d / "scores.npz"),
                     "metrics": read_json(d / "metrics.json", fix)})
    if missing and not c.get("partial"):
        example = run_dir(recipe_root(c["runs_root"], recipe, switch), config, c["clip_len"], missing[0])
        raise FileNotFoundError(f"{len(missing)} recipe run(s) missing, e.g. {example / 'metrics.json'}; run the "
                                "train_recipe rule (snakemake) or palpation.apps.train with recipe=... for them "
                                "first (or partial=true for a table of the rows that ran)")
    return runs, missing


def row_groups(c: dict, config: str) -> list[tuple[str, str]]:
    """(recipe, switch_off) of the rows of `config`: each full recipe, then robust minus each switch where
    `switch_experiments` (null: every configuration) lists it."""
    switched = c["experiments"] if c.get("switch_experiments") is None else c["switch_experiments"]
    return [(r, FULL) for r in c["recipes"]] + [("robust", s) for s in c["switches"] if config in switched]


def trajectory_check(full: list[dict], runs: list[dict]) -> dict:
    """Runs of a switch in SAME_TRAJECTORY against the full robust recipe's, seed by seed over the epochs both ran:
    the largest differences of train loss (relative) and val FG IoU / AP. Near 0 says both jobs trained on the
    same Sim set with the same code (a check across device sessions whose Sim set was rebuilt)."""
    history = {r["seed"]: r["metrics"].get("history") or [] for r in full}
    epochs, loss, diffs = 0, 0.0, {"val/fg_iou": 0.0, "val/ap": 0.0}
    for r in runs:
        for a, b in zip(history.get(r["seed"], []), r["metrics"].get("history") or []):
            epochs += 1
            loss = max(loss, abs(a["train/loss"] - b["train/loss"]) / abs(a["train/loss"]))
            for k in diffs:
                if k in a and k in b:
                    diffs[k] = max(diffs[k], abs(a[k] - b[k]))
    return {"epochs_compared": epochs, "max_rel_train_loss": loss, "max_abs_val_fg_iou": diffs["val/fg_iou"],
            "max_abs_val_ap": diffs["val/ap"]}


def kept_validation(metrics: dict) -> tuple[float, int]:
    """(val AP, epoch) of the checkpoint a run kept, from its history (val AP is logged where the recipe selects by
    it; nan otherwise): the validation-only evidence for choosing a recipe, never the test columns."""
    history, best = metrics.get("history") or [], int(metrics.get("best_epoch", -1))
    ap = history[best].get("val/ap", float("nan")) if 0 <= best < len(history) else float("nan")
    return float(ap), best


def group_row(config, recipe, switch, runs, maps, settings, layout) -> tuple[dict, list, dict]:
    """The ablation row of one (config, recipe, switch) over its seeds, their map stacks and scores."""
    aurocs = [r["metrics"]["test"]["auroc"] for r in runs]
    aps = [r["metrics"]["test"]["ap"] for r in runs]
    stacks, scores, d_bars, shares, eces = [], [], [], [], []
    for r in runs:
        source, s = source_for(maps, config, r, layout)
        res = config_maps(config, source, **s, settings=settings)
        stacks.append(res.stack)
        d_bars.append(res.stats["d_bar_mm"])
        shares.append(positive_share(s["probs"]))
        eces.append(ece(s["probs"], s["labels"]))
        scores.append(s)
    sd = (lambda v: float(np.std(v, ddof=1)) if len(v) > 1 else float("nan"))
    row = {"config": config, "recipe": recipe, "switch_off": switch, "seeds": len(runs),
           "auroc_mean": float(np.mean(aurocs)), "auroc_std": sd(aurocs), "ap_mean": float(np.mean(aps)),
           "ap_std": sd(aps), "pos_share_05": float(np.mean(shares)), "ece": float(np.mean(eces)),
           "d_bar_mm": float(np.nanmean(d_bars))}
    kept = [kept_validation(r["metrics"]) for r in runs]
    row["val_ap_kept"] = float(np.mean([v for v, _ in kept]))  # recipe_report.json only: not a table column
    row["kept_epochs"] = [e for _, e in kept]
    return row, stacks, scores


def run(cfg: DictConfig) -> dict:
    c = OmegaConf.to_container(cfg, resolve=True)
    c.pop("hydra", None)
    out = Path(c["out_dir"])
    unknown = [k for k in c["experiments"] if k not in TEST_DATASET]
    if unknown:
        raise ValueError(f"unknown configuration(s) {unknown} in experiments; use {sorted(TEST_DATASET)}")
    maps = maps_config(c)
    settings = MapSettings(max_grid_px=int(maps["max_grid_px"]), sim_max_maps=maps["sim"]["max_maps"],
                           sim_vessel_only=bool(maps["sim"]["vessel_only"]), **maps["threshold"])
    layout = silicone_layout(maps)[0] if any(TEST_DATASET[k] == "silicone" for k in c["experiments"]) else None
    rows, unc_rows, ens_maps, curves, panels, summary, left_out = [], [], {}, {}, {}, {}, []
    full_robust, checks = {}, {}
    for config in c["experiments"]:
        title = f"{config} ({CONFIG_TITLES.get(config, config)})"
        for recipe, switch in row_groups(c, config):
            runs, missing = load_group(c, config, recipe, switch)
            if missing:  # partial: a row is all its seeds or left out, never a mean of fewer
                left_out.append({"config": config, "recipe": recipe, "switch_off": switch, "missing_seeds": missing})
                log.warning("%s %s -%s left out: runs of seeds %s missing", config, recipe, switch, missing)
                continue
            row, stacks, scores = group_row(config, recipe, switch, runs, maps, settings, layout)
            rows.append(row)
            if recipe == "robust" and switch == FULL:
                full_robust[config] = runs
            elif recipe == "robust" and switch in SAME_TRAJECTORY and config in full_robust:
                checks[f"{config}/robust-{switch}"] = trajectory_check(full_robust[config], runs)
            log.info("%s %s -%s: AP %.4f ± %.4f, positive at 0.5 %.1f %%, ECE %.4f, d-bar %.2f mm", config, recipe,
                     switch, row["ap_mean"], row["ap_std"], 100 * row["pos_share_05"], row["ece"], row["d_bar_mm"])
            if switch != FULL:
                continue
            labels = np.concatenate([s["labels"] for s in scores])
            panels.setdefault(title, {})[f"{recipe} ({len(runs)} seeds)"] = (
                np.concatenate([s["probs"] for s in scores]), labels)
            # the seeds as an ensemble: per marker, and per pixel of the vessel map
            mean, spread = ensemble([s["probs"] for s in scores])
            marker_curve = coverage_curve(mean, spread, scores[0]["labels"].astype(bool), c["threshold"])
            ens = ensemble_map(stacks, c["threshold"])
            pixel_curve = ens.coverage_curve(settings.tolerance_mm)
            name = f"{config}/{recipe}"
            unc_rows += [{"config": name, **r} for r in pixel_curve]
            ens_maps[name], curves[name] = ens, pixel_curve
            save_npz(out / f"ensemble_{config}_{recipe}.npz", marker_mean=mean.astype(np.float32),
                     marker_spread=spread.astype(np.float32), labels=scores[0]["labels"], map_mean=ens.mean,
                     map_spread=ens.spread, map_visited=ens.visited, map_truth=ens.truth, map_unsure=ens.unsure)
            summary[name] = {"seeds": [r["seed"] for r in runs], "marker_coverage": marker_curve,
                             "pixel_coverage": pixel_curve, "unsure_pixels": int(ens.unsure.sum()),
                             "visited_pixels": int(ens.visited.sum()),
                             "calibration": [r["metrics"].get("calibration") for r in runs]}
    if not rows:
        raise FileNotFoundError(f"no recipe row has all its runs under {c['runs_root']} (seeds {c['seeds']}); "
                                "train them first (rule train_recipe)")
    table, unc = recipe_ablation(rows), uncertainty_table(unc_rows)
    for df, name in ((table, "recipe_ablation.csv"), (unc, "uncertainty.csv")):
        with atomic_path(out / name) as tmp:
            df.to_csv(tmp, index=False, float_format="%.6g")
    notes = [f"Seeds {c['seeds']}, clip length {c['clip_len']}; positive share and ECE ({15} equal-width bins) are "
             "means over seeds of the test scores as written (calibrated where the recipe calibrates); d̄ from each "
             "seed's vessel map at its SPEC §12 threshold (chosen on the test map, quirk 18), averaged.",
             "Calibration and early stopping use the training domain's validation split only."]
    val_rows = [r for r in rows if r["val_ap_kept"] == r["val_ap_kept"]]
    if val_rows:
        kept = [f"{r['config']} {r['recipe']}{'' if r['switch_off'] == FULL else ' minus ' + r['switch_off']} "
                f"{r['val_ap_kept']:.4f} (epochs {r['kept_epochs']})" for r in val_rows]
        notes.append("Validation AP of the kept checkpoints (the training domain's val split; what a recipe choice may "
                     "read): " + "; ".join(kept) + ".")
    if checks:
        worst = max(checks.values(), key=lambda v: v["max_abs_val_fg_iou"])
        notes.append(f"Same training as the full robust recipe where a switch only changes where training stops or "
                     f"how scores are rescaled ({', '.join(sorted(checks))}), epoch by epoch: train loss within "
                     f"{max(v['max_rel_train_loss'] for v in checks.values()):.1e} (relative), val FG IoU within "
                     f"{worst['max_abs_val_fg_iou']:.1e} over {sum(v['epochs_compared'] for v in checks.values())} "
                     "seed-epochs (recipe_report.json `trajectory_checks`).")
    if left_out:
        notes.append(partial_note(left_out, c.get("partial_reason")))
    save_text(out / "recipe_ablation.md", recipe_ablation_markdown(table, c["profile"], notes))
    save_figure(reliability_figure(panels, f"Reliability of the test scores ({c['profile']} profile)"),
                out / "reliability")
    save_figure(uncertainty_figure(ens_maps, curves, f"Seed ensembles ({c['profile']} profile): threshold "
                                   f"{c['threshold']:g} on the mean; unsure = mean ± 1 std crosses it"),
                out / "uncertainty_maps")
    save_json(out / "recipe_report.json", {"profile": c["profile"], "rows": rows, "ensembles": summary,
                                           "partial": bool(c.get("partial")), "left_out": left_out,
                                           "trajectory_checks": checks,
                                           "partial_reason": c.get("partial_reason")})
    if c.get("track"):
        _track(c, rows, out)
    return {"table": rows, "uncertainty": unc_rows, "ensembles": summary, "left_out": left_out}


def partial_note(left_out: list[dict], reason: str | None) -> str:
    """One line naming the rows a partial table leaves out (and why, where the caller said)."""
    names = "; ".join(f"{r['config']} {r['recipe']}"
                      f"{'' if r['switch_off'] == FULL else ' minus ' + r['switch_off']} (seeds {r['missing_seeds']})"
                      for r in left_out)
    return (f"Partial table: {len(left_out)} row(s) left out because their runs are missing: {names}."
            + (f" Why: {reason}" if reason else ""))


def _track(c: dict, rows: list[dict], out: Path) -> None:
    params = {k: c.get(k) for k in ("profile", "experiments", "recipes", "switches", "switch_experiments", "seeds",
                                    "clip_len", "threshold")}
    with tracking.start_run("recipe_report", params, config=c['profile']):
        for r in rows:
            key = f"{r['config']}/{r['recipe']}/{r['switch_off']}"
            tracking.log_metrics({f"{key}/{k}": r[k] for k in ("auroc_mean", "ap_mean", "ap_std", "pos_share_05",
                                                                "ece", "d_bar_mm") if r[k] == r[k]})
        for name in ("recipe_ablation.csv", "recipe_ablation.md", "uncertainty.csv", "recipe_report.json"):
            tracking.log_artifact(out / name)
        for stem in ("reliability", "uncertainty_maps"):
            tracking.log_figure(out / stem)


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="recipe_report")
@app_main("recipe_report", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
