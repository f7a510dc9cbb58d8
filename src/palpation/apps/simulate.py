"""Hydra entry point: simulate a named trajectory set and write npz files + a manifest.

Sets (conf/simulate.yaml): `canonical` (the four calibration interactions, vessel-free, reference
parameters), `vessel_slide` (one slide over the vessel), `randomised` (the SPEC §7 draws:
heading offset, k_n, c_n per trial from one default_rng(seed) stream; even files have the vessel) and
`depth_bank` (vessel-free slides at the known depths `bank_depths_mm`: the lookup of palpation.transfer.latent).
`dataset.depths_from` (null: SPEC's one slide depth) draws each randomised pair's depth over the real slides'
estimated depths (a CSV of workflow/scripts/latent_depth.py; docs/transfer.md), from a stream of its own.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from palpation.config_check import app_main
from palpation.config_ranges import SEED, Choice, Int, ListOf, Num, Text
from palpation.twin.config import REF_LENGTH_SCALE, TwinConfig, from_reference_units
from palpation.twin.mesh import SensorMesh
from palpation.twin.output import copy_outputs, read_sim_manifest, write_outputs
from palpation.twin.runner import EnvRequest, run_batches
from palpation.twin.trajectory import MAX_DEPTH_MM

log = logging.getLogger(__name__)
SETS = ("canonical", "vessel_slide", "randomised", "depth_bank")
# settings of conf/simulate.yaml, checked before any work (config_ranges); the twin's are on TwinConfig
RANGES = {"set": Choice(*SETS), "seed": SEED, "heading_offset_deg": Num(ge=-180, le=180), "n_pairs": Int(ge=1),
          "batch_size": Int(ge=1), "workers": Int(ge=0), "max_frames": Int(ge=1, null=True),
          "reuse": ListOf(Text(), 0), "dataset.depths_from": Text(null=True),
          "bank_depths_mm": ListOf(Num(ge=0, le=MAX_DEPTH_MM), 2, unique=True, increasing=True)}

CANONICAL = ("press", "twist_z", "twist_x", "slide")
HEADING_RANGE_DEG = (-15.0, 15.0)  # SPEC §7 draws, k_n in reference units (x5 length scale)
K_N_REF_RANGE = (5e3, 5e4)
C_N_RANGE = (0.0, 100.0)


def k_n_draw_range(recentre_on: float | None = None) -> tuple[float, float]:
    """SPEC §7's k_n range in reference units, or the same log-width centred on a fitted k_n.

    The paper's fitted k_n (94,908) lies outside its own draw range (quirk 4); `recentre_on` (reference
    units) moves the range's geometric centre onto the fit so the two can be compared.
    """
    lo, hi = K_N_REF_RANGE
    if recentre_on is None:
        return lo, hi
    if not recentre_on > 0:
        raise ValueError(f"recentre_k_n: the fitted k_n must be > 0, got {recentre_on}")
    half = np.sqrt(hi / lo)
    return recentre_on / half, recentre_on * half


def trajectory_set(name: str, seed: int, n_pairs: int = 1,
                   heading_offset_deg: float = 0.0,
                   k_n_ref_range: tuple[float, float] = K_N_REF_RANGE, depths_mm=None) -> list[EnvRequest]:
    """The EnvRequests of a named set; parameters left None come from the twin config. `depths_mm`: randomised,
    one slide depth per pair (None: SPEC's); depth_bank, the bank's depths."""
    if name == "canonical":
        return [EnvRequest(kind=k, vessel=False, seed=seed, name=k) for k in CANONICAL]
    if name == "vessel_slide":
        return [EnvRequest(kind="slide", heading_offset_deg=heading_offset_deg, vessel=True, seed=seed,
                           name="vessel_slide")]
    if name == "randomised":
        rng = np.random.default_rng(seed)
        out = []
        for i in range(n_pairs):
            for j in (0, 1):  # all three draws happen for every trial, vessel or not
                heading = rng.uniform(*HEADING_RANGE_DEG)
                k_n = from_reference_units(k_n=rng.uniform(*k_n_ref_range))["k_n"]
                c_n = rng.uniform(*C_N_RANGE)
                depth = None if depths_mm is None else float(depths_mm[i])
                out.append(EnvRequest(kind="slide", heading_offset_deg=heading, k_n=k_n, c_n=c_n,
                                      vessel=j == 0, seed=seed, name=f"trajectory_{2 * i + j:04d}", depth_mm=depth))
        return out
    if name == "depth_bank":
        if depths_mm is None or len(depths_mm) < 2:
            raise ValueError("set=depth_bank needs bank_depths_mm, at least two depths (mm)")
        return [EnvRequest(kind="slide", heading_offset_deg=heading_offset_deg, vessel=False, seed=seed,
                           name=f"bank_{i:02d}", depth_mm=float(d)) for i, d in enumerate(depths_mm)]
    raise ValueError(f"unknown trajectory set '{name}': use one of {SETS}")


def set_depths(cfg: DictConfig) -> list[float] | None:
    """The depths the set's requests take: depth_bank's bank, or randomised pairs' draws over the real slides'
    estimated depths (`dataset.depths_from`); None: SPEC's one slide depth."""
    if cfg.set == "depth_bank":
        return [float(d) for d in cfg.get("bank_depths_mm") or []]
    source = cfg.get("dataset", {}).get("depths_from")
    if source is None or cfg.set != "randomised":
        return None
    from palpation.transfer.latent import draw_depths, read_estimates

    return draw_depths(read_estimates(source), cfg.n_pairs, cfg.seed).tolist()


def request_key(cfg: DictConfig, k_n_range: tuple[float, float]) -> str:
    """sha256 of everything that decides a set's trajectories: the draws, the frame cut, the twin and the mesh file.
    Not the batch size or threads (they change no record: twin.runner.run_batches) or the output folder. The depths
    enter only where a set has its own (so every other set keeps its key)."""
    spec = {"set": cfg.set, "seed": cfg.seed, "n_pairs": cfg.n_pairs, "heading_offset_deg": cfg.heading_offset_deg,
            "k_n_range": list(k_n_range), "max_frames": cfg.max_frames,
            "twin": OmegaConf.to_container(cfg.twin, resolve=True),
            "mesh_sha256": hashlib.sha256(Path(cfg.mesh).read_bytes()).hexdigest()}
    depths = set_depths(cfg)
    if depths is not None:
        spec["depths_mm"] = depths
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()


def reusable(paths, key: str) -> Path | None:
    """The first manifest of `paths` (config `reuse`) whose set was made from the same request key, else None."""
    for path in paths or []:
        meta, _ = read_sim_manifest(path, "name manifest.json files of finished sets in `reuse`, or reuse=[]",
                                    allow_empty=True)
        if meta.get("request_key") == key and not meta.get("failed"):
            return path
    return None


def run(cfg: DictConfig) -> dict:
    twin: TwinConfig = OmegaConf.to_object(cfg.twin)
    if cfg.set == "depth_bank" and not twin.contact.phantom_contact:
        # the reference twin has no phantom surface: a vessel-free slide then moves no marker at any depth
        raise ValueError("set=depth_bank: the twin has no phantom surface (twin.contact.phantom_contact=false), so its "
                         "vessel-free slides look the same at every depth; make the bank with the surface contact on, "
                         "e.g. twin.contact.phantom_contact=true twin.contact.k_s=<the loop's fitted k_s>")
    mesh = SensorMesh.load(cfg.mesh)  # checked first: its bytes are hashed into the request key
    # quirk 4: optionally centre the k_n draws on the twin's (fitted) k_n, in reference units
    centre = twin.contact.k_n * REF_LENGTH_SCALE if cfg.dataset.recentre_k_n else None
    k_n_range = k_n_draw_range(centre)
    key = request_key(cfg, k_n_range)
    same = reusable(cfg.get("reuse"), key)
    if same is not None:  # the same trajectories exist (e.g. the chosen twin's candidate set): copy, not re-simulate
        manifest = copy_outputs(same, cfg.out.dir, {"reused_from": str(same)})
        log.info("same request key as %s: its files copied to %s, nothing simulated", same, cfg.out.dir)
        return _tracked(cfg, {"manifest": str(manifest), "n_files": len(read_sim_manifest(manifest)[1]),
                              "n_failed": 0, "reused": 1})
    requests = trajectory_set(cfg.set, cfg.seed, cfg.n_pairs, cfg.heading_offset_deg, k_n_range, set_depths(cfg))
    records, failed = [], []
    start = time.perf_counter()
    for res in run_batches(mesh, twin, requests, cfg.batch_size, device=twin.device, progress=cfg.progress,
                           max_frames=cfg.max_frames, workers=cfg.get("workers") or None):
        records += res.records
        failed += res.failed
    wall = time.perf_counter() - start  # the batches' wall time (side by side in threads on a CPU)
    meta = {"set": cfg.set, "seed": cfg.seed, "mesh": str(cfg.mesh), "resolution": mesh.resolution,
            "device": twin.device, "sim_wall_s": wall, "max_frames": cfg.max_frames,
            "twin": OmegaConf.to_container(cfg.twin, resolve=True), "request_key": key}
    manifest = write_outputs(Path(cfg.out.dir), records, failed, meta=meta)
    summary = {"manifest": str(manifest), "n_files": len(records), "n_failed": len(failed), "reused": 0,
               "sim_wall_s": wall, "total_wall_s": time.perf_counter() - start}
    for rec in records:
        log.info("%s: %s, %d frames, %d with contact, positive rate %.4f", rec.name, rec.kind,
                 len(rec.markers), rec.contact.sum(), rec.labels.mean())
    for bad in failed:
        log.warning("FAILED %s (%s) by frame %d: %s", bad.name, bad.kind, bad.detected_at_frame, bad.params)
    if requests and not records:  # nothing usable: fail the job, the manifest says which diverged
        raise ValueError(f"all {len(failed)} trajectories diverged, none written (failures listed in {manifest}); "
                         "check the twin's stiffness and time step (twin.material.E, twin.contact.k_n, twin.integrator.dt)")
    return _tracked(cfg, summary)


def _tracked(cfg: DictConfig, summary: dict) -> dict:
    if cfg.track:
        from palpation.tracking import log_metrics, start_run

        with start_run("simulate", params=OmegaConf.to_container(cfg, resolve=True)):
            log_metrics({k: float(v) for k, v in summary.items() if k != "manifest"})
    return summary


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="simulate")
@app_main("simulate", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
