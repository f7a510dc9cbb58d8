"""Hydra entry point: rebuild the real Meat set from the A-to-C prediction viewer (SPEC §13.5).

Outputs: `out.npz` (markers (219, 127, 2) sensor px, labels, the reference model's hard predictions
`ref_hard_pred`, trial / frame / state per row, `trial_offsets`, the panel->sensor similarities and
fit residuals), `out.json` (trials, descriptions, state ranges, SPEC §10 splits, counts) and the
overview figure. Everything is computed before the first file is written.
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from palpation.figures.realdata import meat_overview
from palpation.config_check import app_main
from palpation.config_ranges import Choice, Int, ListOf
from palpation.io import save_figure, save_json, save_npz
from palpation.markers.template import rest_template
from palpation.realdata.meat import N_STATES, SCOPES, build_meat, metadata
from palpation.realdata.panels import read_states

log = logging.getLogger(__name__)
RANGES = {"similarity_scope": Choice(*SCOPES),  # checked before any work (config_ranges)
          "overview_states": ListOf(Int(ge=0, le=N_STATES - 1), unique=True)}


def run(cfg: DictConfig) -> dict:
    video = Path(cfg.video)
    panels = read_states(video, ["ground_truth", "hard_prediction"], progress=bool(cfg.progress))
    template = rest_template(cfg.template_photo)
    data = build_meat(panels["ground_truth"], panels["hard_prediction"], template,
                      scope=cfg.similarity_scope, source=str(video))
    meta = metadata(data, cfg.similarity_scope, str(video))
    fig = meat_overview(data, list(cfg.overview_states)) if cfg.figure else None

    save_npz(cfg.out.npz, **data)
    save_json(cfg.out.json, meta)
    if fig is not None:
        import matplotlib.pyplot as plt

        save_figure(fig, cfg.out.figure)
        plt.close(fig)
    _log_summary(meta)
    if cfg.track:
        _track(cfg, meta)
    return meta


def _log_summary(meta: dict) -> None:
    log.info("%d states x %d markers: %d of %d nodes positive, %d states without positives, max %d",
             meta["n_states"], meta["n_markers"], meta["positives"], meta["nodes"],
             meta["states_without_positives"], meta["max_positives_per_state"])
    log.info("similarity scope %s: %s", meta["similarity_scope"], meta["similarities"][:3])
    for t in meta["trials"]:
        log.info("trial %2d %-34s %-5s states %3d-%3d frames %2d-%2d: %3d positives, fit residual "
                 "median %.2f max %.2f px, max step %.1f px", t["trial_id"], t["description"], t["split"],
                 *t["states"], *t["frames"], t["positives"], t["fit_residual_px_median"],
                 t["fit_residual_px_max"], t["max_step_px"])
    log.info("reference hard predictions: %d positives, accuracy %.4f; tracking slips at states %s",
             meta["ref_hard_positives"], meta["ref_hard_accuracy"], meta["states_with_tracking_jumps"])


def _track(cfg: DictConfig, meta: dict) -> None:
    from palpation.tracking import log_metrics, start_run

    metrics = {"meat/positives": meta["positives"], "meat/positive_rate": meta["positives"] / meta["nodes"],
               "meat/fit_residual_px_median": meta["fit_residual_px"]["median"],
               "meat/fit_residual_px_max": meta["fit_residual_px"]["max"],
               "meat/ref_hard_accuracy": meta["ref_hard_accuracy"]}
    with start_run("meat", params=OmegaConf.to_container(cfg, resolve=True)):
        log_metrics(metrics)


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="meat")
@app_main("meat", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
