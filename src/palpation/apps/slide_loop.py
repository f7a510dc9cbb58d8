"""Hydra entry point: the residual loop on measured slides (docs/slides.md).

Reads a sequence set (`sequences`), keeps `trials` and `frames`, and runs slides.loop with the twin
of the real scene (slides.replay). Writes `out.csv` (one row per fold and round: fold, round, effect_added,
mae_fit_px, mae_heldout_px, vessel_ratio_sim, vessel_ratio_real: the MAE of marker motion about each
trial's median; then mae_abs_heldout_px: the absolute error, at_bounds, and the inner gate's mae_inner_cv_px and
gate_p) and `out.json` (parameters per round, every gated try under `gate`).
"""

from __future__ import annotations

import dataclasses
import logging
import time

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from palpation.config_check import app_main
from palpation.config_ranges import SEED, Choice, DictOf, Int, ListOf, Num
from palpation.io import csv_text, save_json, save_text
from palpation.measured_sequences import SequenceSet, load_sequence_set
from palpation.slides.gate import TESTS, GateSettings
from palpation.slides.loop import COLUMNS, SAMPLERS, SearchSettings, SlideLoopSettings, run_slide_loop
from palpation.slides.replay import frame_mae, frame_mae_abs, make_scene, replay_many
from palpation.slides.selection import select
from palpation.twin.config import TwinConfig
from palpation.twin.markers import bind_markers
from palpation.twin.mesh import SensorMesh, cached_sensor_mesh

log = logging.getLogger(__name__)
# checked before any work (config_ranges); the twin's settings are on TwinConfig. Both folds need a trial (slides.folds)
RANGES = {"trials": ListOf(Int(ge=1), 2, unique=True, null=True),
          "frames": ListOf(Int(ge=0), 2, 2, increasing=True, null=True),  # [first, end)
          "lead_in_mm": Num(ge=0), "base": DictOf(Num()), "search.sampler": Choice(*SAMPLERS),
          "search.batches": Int(ge=1), "search.per_batch": Int(ge=1), "search.seed": SEED,
          "gate.inner_folds": Int(ge=2, null=True), "gate.test": Choice(*TESTS), "gate.alpha": Num(gt=0, lt=1),
          "gate.tries": Int(ge=1), "effects": DictOf(min_len=1), "effects.*": DictOf(min_len=1),
          "effects.*.*": ListOf(Num()), "max_rounds": Int(ge=0), "min_improvement_px": Num(ge=0),
          "fold_workers": Choice(1, 2)}


class Replayer:
    """The loop's `evaluate`: candidates replayed in the twin of the real scene. Picklable (the mesh, marker binding
    and scene are built on first use, in whichever process runs the fold)."""

    def __init__(self, twin: TwinConfig, mesh_path: str | None, sset: SequenceSet, lead_in_mm: float):
        self.twin, self.mesh_path, self.sset, self.lead_in_mm = twin, mesh_path, sset, lead_in_mm
        self._built = None

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_built": None}

    def __call__(self, part: SequenceSet, candidates: list[dict]):
        return self.many([(part, candidates)])[0]

    def many(self, jobs: list[tuple[SequenceSet, list[dict]]]):
        """Several (trials, candidates) replays in one twin batch (the folds' calls with `batch_folds`)."""
        if self._built is None:
            mesh = SensorMesh.load(self.mesh_path) if self.mesh_path else cached_sensor_mesh(self.twin.mesh.resolution)
            self._built = (mesh, bind_markers(mesh.nodes, mesh.dome_nodes, self.sset.rest), make_scene(self.sset))
        mesh, binding, scene = self._built
        start = time.perf_counter()
        out = replay_many(mesh, self.twin, binding, jobs, scene, device=self.twin.device, lead_in_mm=self.lead_in_mm)
        # the loop's cost is its twin calls: their sizes and times say what a faster kernel or a larger batch buys
        log.info("replay: %s envs (candidates x trials) in %.2f s",
                 " + ".join(f"{len(c)} x {p.n_trials}" for p, c in jobs), time.perf_counter() - start)
        return out


def run(cfg: DictConfig) -> dict:
    twin: TwinConfig = OmegaConf.to_object(cfg.twin)
    grid = OmegaConf.to_container(cfg.effects, resolve=True)
    settings = SlideLoopSettings(effects=grid, base=OmegaConf.to_container(cfg.base, resolve=True),
                                 max_rounds=int(cfg.max_rounds),
                                 min_improvement_px=float(cfg.min_improvement_px),
                                 search=SearchSettings(**OmegaConf.to_container(cfg.search, resolve=True)),
                                 gate=GateSettings(**OmegaConf.to_container(cfg.gate, resolve=True))).validate()
    lead_in = float(cfg.lead_in_mm)
    if lead_in < 0:
        raise ValueError(f"conf/slide_loop.yaml: lead_in_mm = {lead_in} must be >= 0 (mm slid in before frame 0)")
    sset = load_sequence_set(cfg.sequences)
    sub, numbers = select(sset, cfg.trials, cfg.frames)
    workers = int(cfg.fold_workers)
    if workers not in (1, 2):
        raise ValueError(f"conf/slide_loop.yaml: fold_workers = {workers}; use 1 (folds in turn) or 2 (side by side)")
    if cfg.batch_folds and workers != 1:
        raise ValueError("conf/slide_loop.yaml: batch_folds runs both folds in this process (their twin calls as one "
                         "batch); set fold_workers=1 with it")
    start = time.perf_counter()
    result = run_slide_loop(Replayer(twin, cfg.mesh, sset, lead_in), sub, settings, numbers, workers,
                            batch_folds=bool(cfg.batch_folds))
    # the floor a twin must beat: no motion at all (every frame predicted as the rest template)
    still = np.broadcast_to(sub.rest, sub.markers.shape).astype(np.float64)
    for key, fn in (("static_mae_px", frame_mae), ("static_mae_abs_px", frame_mae_abs)):
        per_trial = fn(still, sub)
        result[key] = {f: float(per_trial[[numbers.index(t) for t in ts]].mean()) for f, ts in result["folds"].items()}
    log.info("no-motion floor (rest template as every frame), per fold: motion %s, absolute %s",
             result["static_mae_px"], result["static_mae_abs_px"])
    wall = time.perf_counter() - start
    save_text(cfg.out.csv, csv_text(result["rows"], COLUMNS, 4, na_rep="nan"))
    size = {"trials": numbers, "frames": list(cfg.frames) if cfg.frames is not None else [0, sset.n_frames],
            "mesh": twin.mesh.resolution, "device": str(twin.device)}
    # the judge's replays (apps.twin_judge task=slides) read `replay` so that they replay exactly as the loop scored
    save_json(cfg.out.json, {"sequences": str(cfg.sequences), "size": size, "wall_s": wall, **result,
                             "replay": {"lead_in_mm": lead_in},
                             "settings": dataclasses.asdict(settings)})
    log.info("slide loop: %d rows in %.0f s -> %s", len(result["rows"]), wall, cfg.out.csv)
    return result


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="slide_loop")
@app_main("slide_loop", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
