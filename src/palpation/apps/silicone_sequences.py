"""Hydra entry point: the Silicone set as measured sequences (markers + poses + vessels, one world frame).

Reads the tracked Silicone set (`silicone`, rule silicone_set), adds the reconstructed poses
(mapping.silicone_poses) and the phantom photo's vessel centrelines (mapping.silicone_sequences) and
writes `out.sequences`.{npz,json} in the sequence format (palpation.measured_sequences), which the
slide loop (palpation.apps.slide_loop) reads like any user's own slides.
"""

from __future__ import annotations

import logging

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from palpation.config_check import app_main
from palpation.config_ranges import DictOf, Num
from palpation.readers import read_npz
from palpation.mapping import silicone_sequences as seq
from palpation.mapping.silicone_poses import SweepLayout
from palpation.markers.template import rest_template
from palpation.measured_sequences import save_sequence_set

log = logging.getLogger(__name__)
RANGES = {"depth_mm": Num(gt=0), "bin_mm": Num(gt=0), "layout": DictOf(Num())}  # before any work (config_ranges)
SILICONE_KEYS = ("markers", "found", "labels", "videos")


def run(cfg: DictConfig) -> dict:
    data = read_npz(cfg.silicone, SILICONE_KEYS, fix="rebuild it with python -m palpation.apps.silicone "
                    "(rule silicone_set)")
    fields = SweepLayout.__dataclass_fields__
    layout_over = OmegaConf.to_container(cfg.layout, resolve=True) or {}
    unknown = sorted(set(layout_over) - set(fields))
    if unknown:
        raise ValueError(f"conf/silicone_sequences.yaml: layout has unknown keys {unknown}; use {sorted(fields)}")
    layout = SweepLayout(**layout_over)
    sset = seq.silicone_sequences(data, rest_template(cfg.template_photo), layout, float(cfg.depth_mm),
                                  source=str(cfg.silicone), bin_mm=float(cfg.bin_mm))
    diameters = [v["diameter_mm"] for v in sset.vessels]
    npz, js = save_sequence_set(cfg.out.sequences, sset)
    log.info("%d trials x %d frames, %d vessels (diameters %s mm, %d centreline points) -> %s",
             sset.n_trials, sset.n_frames, len(sset.vessels), [round(d, 2) for d in diameters],
             len(sset.vessel_points_mm), npz)
    return {"trials": sset.n_trials, "frames": sset.n_frames, "vessels": len(sset.vessels),
            "diameters_mm": diameters, "npz": str(npz), "json": str(js),
            "pose_range_mm": np.ptp(sset.pose_mm[..., :2].reshape(-1, 2), axis=0).tolist()}


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="silicone_sequences")
@app_main("silicone_sequences", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
