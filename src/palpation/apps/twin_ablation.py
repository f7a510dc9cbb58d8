"""Hydra entry point: the dataset-twin ablation table (loop twin vs calibration-only twin).

    python -m palpation.apps.twin_ablation twins.loop=results/train \
        twins.calibrated=results/train/twin_calibrated out_dir=results/train/report
Writes twin_ablation.csv and twin_ablation.md into out_dir.
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from palpation.config_check import app_main
from palpation.config_ranges import SEEDS, DictOf, Int, ListOf, Text
from palpation.io import atomic_path, save_text
from palpation.report.runs import load_runs
from palpation.report.twin_ablation import twin_ablation, twin_ablation_markdown

log = logging.getLogger(__name__)
RANGES = {"experiments": ListOf(Text(), unique=True), "seeds": SEEDS, "clip_len": Int(ge=1),  # before any work
          "twins": DictOf(Text(), min_len=1)}


def run(cfg: DictConfig) -> dict:
    c = OmegaConf.to_container(cfg, resolve=True)
    if not c["twins"]:
        raise ValueError("twins: give at least one dataset twin -> runs root, e.g. twins.loop=results/train")
    runs = {twin: load_runs(root, c["experiments"], [c["clip_len"]], c["seeds"]) for twin, root in c["twins"].items()}
    out = Path(c["out_dir"])
    with atomic_path(out / "twin_ablation.csv") as tmp:
        twin_ablation(runs).to_csv(tmp, index=False, float_format="%.6g")
    save_text(out / "twin_ablation.md", twin_ablation_markdown(runs, c["profile"]))
    log.info("twin ablation: %s", {t: len(r) for t, r in runs.items()})
    return {t: len(r) for t, r in runs.items()}


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="twin_ablation")
@app_main("twin_ablation", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
