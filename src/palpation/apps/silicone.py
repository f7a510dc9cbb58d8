"""Hydra entry point: the real Silicone set (task=set) or its label cross-check (task=check).

task=set   -> `out.npz` (markers (10, 16, 127, 2) sensor px, found, source, labels, dots, ...),
              `out.json` (source file, states, frame indices, sweeps, counts, step statistics) and the
              overview figure. Everything is computed before the first file is written.
task=check -> `out.agreement`: per-state agreement of the labels in `out.npz` with the Ground Truth
              panel of the A-to-B prediction viewer; fails if the mean is below `min_agreement`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from palpation.figures.realdata import silicone_overview
from palpation.camera import video_to_sensor_px
from palpation.config_check import app_main
from palpation.config_ranges import Choice, Int, ListOf, Num
from palpation.io import save_figure, save_json, save_npz
from palpation.markers.template import rest_template
from palpation.readers import read_npz
from palpation.realdata import silicone as sil
from palpation.realdata.silicone_check import check_labels

log = logging.getLogger(__name__)
RANGES = {"task": Choice("set", "check"),  # checked before any work (config_ranges); 1-based videos and frames
          "videos": ListOf(Int(ge=1, le=sil.N_VIDEOS), unique=True), "n_frames": Int(ge=1, le=sil.N_FRAMES),
          "min_agreement": Num(ge=0, le=1), "overview": ListOf(ListOf(Int(ge=1, le=sil.N_FRAMES), 2, 2), 0),
          "workers": Int(ge=1)}


def run(cfg: DictConfig) -> dict:
    if cfg.task == "set":
        return _build(cfg)
    if cfg.task == "check":
        return _check(cfg)
    raise ValueError(f"unknown task '{cfg.task}' in conf/silicone.yaml: use task=set or task=check")


def _build(cfg: DictConfig) -> dict:
    params = sil.SiliconeParams(**OmegaConf.to_container(cfg.detector, resolve=True))
    video = Path(cfg.video)
    template = rest_template(cfg.template_photo)
    data = sil.build_silicone_set(video, list(cfg.videos), int(cfg.n_frames), params, template,
                                  progress=bool(cfg.progress), workers=int(cfg.workers))
    meta = metadata(data, video, params)
    fig = silicone_overview(data, video, [tuple(x) for x in cfg.overview]) if cfg.figure else None

    save_npz(cfg.out.npz, **data)
    save_json(cfg.out.json, meta)
    if fig is not None:
        import matplotlib.pyplot as plt

        save_figure(fig, cfg.out.figure)
        plt.close(fig)
    s = meta["summary"]
    log.info("markers: %d detected (%d blob, %d masked fit), %d filled; frames by detected count %s",
             s["detected"], s["detected_blob"], s["detected_masked_fit"], s["filled"],
             s["frames_by_detected_count"])
    log.info("steps (orig px): %s; similarity scale %s", s["step_px"], s["similarity_scale"])
    log.info("dots %d %s in %d states; %d positive marker-frames in %d states (rate %.4f); central "
             "frames %d / %d = %.4f", s["dots"], s["dots_by_colour"], s["states_with_dots"],
             s["positive_marker_frames"], s["states_with_positives"], s["positive_rate"],
             s["central_positives"], s["central_nodes"], s["central_positive_rate"])
    if cfg.track:
        _track(cfg, "silicone", {f"silicone/{k}": v for k, v in s.items() if np.isscalar(v)}
               | {f"silicone/step_px_{k}": v for k, v in s["step_px"].items()})
    return meta


def _check(cfg: DictConfig) -> dict:
    data = read_npz(cfg.out.npz, ("markers", "labels", "chord_distance_px"), "rebuild it with task=set",
                    "Silicone set", shapes={"markers": (None, None, sil.N_MARKERS, 2)})
    markers, labels, distance = data["markers"], data["labels"], data["chord_distance_px"]
    if markers.shape[:2] != (sil.N_VIDEOS, sil.N_FRAMES):
        raise ValueError(f"{cfg.out.npz}: the check needs the full set (10 videos x 16 frames), got "
                         f"{markers.shape[:2]}; rebuild it with task=set and the default videos")
    result = check_labels(markers, labels, cfg.prediction_video, chord_distance=distance)
    log.info("label agreement with the panel: mean %.4f %%, min %.4f %%, %d vs %d panel positives",
             100 * result["mean_agreement"], 100 * result["min_agreement"], result["our_positives"],
             result["panel_positives"])
    if result["mean_agreement"] < cfg.min_agreement:
        raise ValueError(f"label agreement {result['mean_agreement']:.4f} is below min_agreement "
                         f"{cfg.min_agreement}; inspect the per-state list before writing anything")
    save_json(cfg.out.agreement, result)
    if cfg.track:
        _track(cfg, "silicone_check", {"silicone/agreement_mean": result["mean_agreement"],
                                       "silicone/agreement_min": result["min_agreement"]})
    return result


def metadata(data: dict, video: Path, params: sil.SiliconeParams) -> dict:
    """JSON side-car: provenance, state indexing, sweeps and the summary numbers."""
    videos = [int(v) for v in data["videos"]]
    return {
        "source": str(video), "source_sha256": hashlib.sha256(video.read_bytes()).hexdigest(),
        "n_videos": len(videos), "n_frames": int(data["states"].shape[1]), "n_markers": sil.N_MARKERS,
        "state_rule": "state s = video s//16 + 1, frame s%16 + 1; read video frame 5s + 4",
        "videos": [{"video": v, "sweep": sil.SWEEP_NAMES[v - 1], "line_angle_deg": sil.LINE_ANGLE_DEG[v - 1],
                    "states": data["states"][k].tolist(), "frame_index": data["frame_index"][k].tolist()}
                   for k, v in enumerate(videos)],
        "arrays": {"markers": "sensor px (1920x1080), base-graph order",
                   "found": "detected in this frame (blob or masked fit); False = filled from neighbours",
                   "source": "0 filled, 1 clear blob, 2 masked fit of a marker partly under a dot",
                   "labels": "1 iff < 30 px from a chord sample of a dot of the same frame",
                   "chord_distance_px": "distance to the nearest chord sample (inf: no dot)",
                   "dots": "dot centres, sensor px, NaN-padded to 4; dot_colours indexes dot_colours_names"},
        "dot_colours_names": list(sil.DOT_COLOURS),
        "params": dataclasses.asdict(params),
        "summary": sil.summarize(data),
    }


def _track(cfg: DictConfig, stage: str, metrics: dict) -> None:
    from palpation.tracking import log_metrics, start_run

    with start_run(stage, params=OmegaConf.to_container(cfg, resolve=True)):
        log_metrics(metrics)


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="silicone")
@app_main("silicone", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
