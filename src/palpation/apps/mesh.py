"""Hydra entry point: mesh the sensor at one resolution, write the mesh (npz) and its statistics (JSON)."""

from __future__ import annotations

import logging

import hydra
from omegaconf import DictConfig

from palpation.config_check import app_main
import palpation.twin.config  # noqa: F401  (registers base_twin / base_mesh)
from palpation.io import save_json
from palpation.twin.mesh import build_sensor_mesh

log = logging.getLogger(__name__)


def run(cfg: DictConfig) -> dict:
    mesh_cfg = cfg.twin.mesh
    mesh = build_sensor_mesh(mesh_cfg.resolution, length_factor=mesh_cfg.length_factor)
    stats = mesh.stats() | {"length_factor": mesh_cfg.length_factor}
    mesh.save(cfg.out.mesh)
    save_json(cfg.out.stats, stats)
    log.info("mesh %s: %s", mesh_cfg.resolution, stats)
    return stats


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="mesh")
@app_main("mesh")
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
