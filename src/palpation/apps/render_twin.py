"""Hydra entry point: rest-vs-deformed marker figure and one MP4 per simulated trajectory.

    python -m palpation.apps.render_twin manifests=[results/twin/canonical/manifest.json] out.dir=results/twin/render
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
from omegaconf import DictConfig

from palpation.config_check import app_main
from palpation.config_ranges import ListOf, Text
from palpation.figures.twin_render import render

log = logging.getLogger(__name__)
RANGES = {"manifests": ListOf(Text())}  # checked before any work (config_ranges)


def run(cfg: DictConfig) -> list[Path]:
    if not cfg.manifests:
        raise ValueError("render_twin: `manifests` is empty; pass manifests=[<simulate stage manifest.json>, ...]")
    outputs = render([Path(m) for m in cfg.manifests], Path(cfg.out.dir))
    for p in outputs:
        log.info("wrote %s", p)
    return outputs


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="render_twin")
@app_main("render_twin", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
