"""Hydra entry point: gather training runs into tables and Fig. 6 (SPEC §11, §15).

    python -m palpation.apps.train_tables runs_root=results/train out_dir=results/report profile=quick
Writes seed_sweep.{csv,md}, table4_markers.{csv,md}, clip_len_ablation.csv, table3_clip_len.md,
fig6_pr_curves.{png,pdf} and bench_train.json into out_dir.
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
import matplotlib.pyplot as plt
from omegaconf import DictConfig, OmegaConf

from palpation.figures.pr_curves import pr_figure
from palpation.config_check import app_main
from palpation.config_ranges import SEEDS, Int, ListOf, Text
from palpation.io import atomic_path, save_figure, save_json, save_text
from palpation.metrics.aggregate import pr_curve
from palpation.metrics.scores import load_scores
from palpation.report import tables
from palpation.report.runs import load_runs

log = logging.getLogger(__name__)
RANGES = {"experiments": ListOf(Text(), unique=True), "seeds": SEEDS, "clip_len": Int(ge=1),  # before any work
          "ablation.experiment": Text(), "ablation.clip_lens": ListOf(Int(ge=1), 0, unique=True),  # []: no Table 3
          "ablation.seeds": SEEDS}


def save_csv(df, path: Path) -> None:
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False, float_format="%.6g")


def run(cfg: DictConfig) -> dict:
    c = OmegaConf.to_container(cfg, resolve=True)
    out, profile = Path(c["out_dir"]), c["profile"]
    runs = load_runs(c["runs_root"], c["experiments"], [c["clip_len"]], c["seeds"])
    sweep = tables.seed_sweep(runs)
    save_csv(sweep, out / "seed_sweep.csv")
    save_text(out / "seed_sweep.md", tables.seed_sweep_markdown(sweep, profile))
    t4 = tables.table4_markers(runs)
    save_csv(t4, out / "table4_markers.csv")
    save_text(out / "table4_markers.md", tables.table4_markers_markdown(t4, profile))

    curves, chance = {}, {}
    for config in c["experiments"]:
        mine = [r for r in runs if r["config"] == config]
        scores = [load_scores(Path(r["dir"]) / "scores.npz") for r in mine]
        curves[config] = [pr_curve(s.probs, s.labels) for s in scores]
        chance[config] = sum(r["chance"] for r in mine) / len(mine)
    fig = pr_figure(curves, chance, f"{profile} profile, L = {c['clip_len']}, seeds {c['seeds']}")
    save_figure(fig, out / "fig6_pr_curves")
    plt.close(fig)

    outputs = {"runs": len(runs)}
    abl = c["ablation"]
    if abl["clip_lens"]:
        abl_runs = load_runs(c["runs_root"], [abl["experiment"]], abl["clip_lens"], abl["seeds"])
        t3 = tables.clip_len_ablation(abl_runs)
        save_csv(t3[list(tables.ABLATION_COLUMNS)], out / "clip_len_ablation.csv")
        save_text(out / "table3_clip_len.md", tables.table3_markdown(t3, profile))
        outputs["ablation_runs"] = len(abl_runs)
        runs = runs + [r for r in abl_runs if r["clip_len"] != c["clip_len"]]
    save_json(out / "bench_train.json", {"profile": profile, "runs": [
        {k: r[k] for k in ("config", "clip_len", "seed", "train_seconds", "device")} for r in runs]})
    log.info("report from %s into %s: %s", c["runs_root"], out, outputs)
    if c["track"]:
        _track(c, out, sweep)
    return outputs


def _track(c: dict, out: Path, sweep) -> None:
    """One MLflow run of the tables: the per-config means as metrics, tables and Fig. 6 as artefacts."""
    from palpation import tracking

    with tracking.start_run("train_tables", {k: c[k] for k in ("runs_root", "experiments", "seeds", "clip_len")}):
        means = sweep.groupby("config")[["auroc", "ap"]].mean()
        tracking.log_metrics({f"{config}/{k}": v for config, row in means.iterrows() for k, v in row.items()})
        for name in ("seed_sweep.csv", "table4_markers.csv", "clip_len_ablation.csv", "bench_train.json"):
            if (out / name).exists():
                tracking.log_artifact(out / name, "tables")
        tracking.log_figure(out / "fig6_pr_curves")


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="train_tables")
@app_main("train_tables", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
