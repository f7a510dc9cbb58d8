"""Twin throughput: substeps/s and slides/hour for batches of N envs at each mesh resolution.

Times the whole pipeline of a slide batch (FEM substeps, contact, per-frame marker extraction) with
`run_batch`, and adds the bare FEM core and its roofline fraction (`twin.bench.time_substeps`).
By default every point times one FULL 398-frame slide batch (`wall_s_measured`, warm kernels) and a
1-frame batch of the same envs; their difference over 397 frames gives the time per frame.
Only with `--budget-s` (or `--max-frames` < 398; the 2-core CPU needs it) are fewer frames timed,
and then the record says so in its field names: `wall_s_extrapolated`, `extrapolated_from_frames`,
`trajectories_per_hour_extrapolated`. Every field of the JSON is written here.

    python -m palpation.twin.benchmark --device cuda:0 --out results/bench/twin.json
    python -m palpation.twin.benchmark --device cpu --budget-s 20 --out results/bench/twin.json
    python -m palpation.twin.benchmark --device cuda:0 --kernel resident --resolutions reference \
        --n-envs 500 --out results/bench/twin_resident.json     # the frame-resident kernel (issue 17)
    python -m palpation.twin.benchmark --device cuda:0 --kernel resident --resolutions reference \
        --n-envs 500 --variants tiles onesync packed packed:largest_first atomic   # its variants
    python -m palpation.twin.benchmark --device cpu --kernel auto --resolutions coarse --n-envs 40   # the CPU's auto
    python -m palpation.twin.benchmark --device cuda:0 --kernel resident --resolutions reference --layered \
        --n-envs 8 32 128 264 --max-frames 40   # the residual loop's layered kernel at its batch sizes
"""

from __future__ import annotations

import argparse
import copy
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

from palpation.io import save_json
from palpation.tracking import git_commit
from palpation.twin.agreement import LAYERED, twin_config
from palpation.twin.bench import time_substeps
from palpation.twin.config import RESIDENT_COLORINGS, RESIDENT_VARIANTS, TwinConfig
from palpation.twin.markers import bind_markers
from palpation.twin.mesh import SensorMesh
from palpation.twin.runner import EnvRequest, run_batch
from palpation.twin.trajectory import plan_trajectory

log = logging.getLogger(__name__)
SLIDE_FRAMES = plan_trajectory("slide").n_frames  # 398


def slide_requests(n: int, seed: int = 0) -> list[EnvRequest]:
    """n slides, half over the vessel, headings drawn as in SPEC §7 (contact work is realistic)."""
    rng = np.random.default_rng(seed)
    return [EnvRequest(kind="slide", heading_offset_deg=float(rng.uniform(-15, 15)), vessel=i % 2 == 0,
                       name=f"bench_{i:04d}") for i in range(n)]


def timed_batch(mesh, cfg, reqs, binding, device, frames: int) -> float:
    start = time.perf_counter()
    run_batch(mesh, cfg, reqs, binding=binding, device=device, progress=False, max_frames=frames)
    wp.synchronize_device(device)
    return time.perf_counter() - start


def bench_point(mesh: SensorMesh, cfg: TwinConfig, n_envs: int, device: str, max_frames: int = SLIDE_FRAMES,
                budget_s: float | None = None) -> dict:
    """One record: a timed slide batch of `k` frames (398 unless a budget or max_frames cuts it)."""
    from palpation.markers.template import rest_template

    binding = bind_markers(mesh.nodes, mesh.dome_nodes, rest_template())
    reqs = slide_requests(n_envs)
    timed_batch(mesh, cfg, reqs[:1], binding, device, 1)  # compile/load kernels outside the timing
    t1 = timed_batch(mesh, cfg, reqs, binding, device, 1)
    k = min(max_frames, SLIDE_FRAMES)
    if budget_s is not None:  # a probe of 2 frames tells how many frames fit the budget
        probe = max(timed_batch(mesh, cfg, reqs, binding, device, 2) - t1, 1e-9)
        k = int(min(k, max(2, budget_s / probe)))
    if k < 2:
        raise ValueError(f"--max-frames={max_frames}: time at least 2 frames (398 = a full slide)")
    tk = timed_batch(mesh, cfg, reqs, binding, device, k)
    per_frame = max((tk - t1) / (k - 1), 1e-9)
    setup = max(t1 - per_frame, 0.0)
    substeps = cfg.integrator.substeps
    rec = {"device": device_name(device), "resolution": mesh.resolution, "n_envs": n_envs,
           "frames": SLIDE_FRAMES, "frames_timed": k, "substeps_per_frame": substeps,
           "substeps_per_s": substeps / per_frame, "env_substeps_per_s": n_envs * substeps / per_frame,
           "setup_s": setup, "nodes": mesh.n_nodes, "tets": mesh.n_tets, "commit": git_commit(),
           "kernel": cfg.integrator.kernel, "layered": cfg.layered}
    if cfg.integrator.kernel == "resident":
        ig = cfg.integrator
        rec.update(block_dim=ig.block_dim, resident_variant=ig.resident_variant,
                   resident_coloring=ig.resident_coloring)
    if k == SLIDE_FRAMES:  # the whole batch was timed: no estimate in the record
        rec.update(wall_s_measured=tk, trajectories_per_hour=n_envs * 3600.0 / tk)
    else:
        wall = setup + per_frame * SLIDE_FRAMES
        rec.update(extrapolated_from_frames=k, wall_s_extrapolated=wall,
                   trajectories_per_hour_extrapolated=n_envs * 3600.0 / wall)
    # the bare FEM core (no markers, no host reads) and its memory-bandwidth roofline
    cuda = wp.get_device(device).is_cuda
    small = cuda or n_envs * mesh.n_tets <= 200_000  # a full frame of substeps is cheap enough
    n_core = 124 if small else 16
    core = time_substeps(mesh, n_envs, n_substeps=n_core, device=device,
                         cfg=copy.deepcopy(cfg), repeats=3 if cuda else 1)  # time_substeps edits cfg
    rec.update({"core_substeps_timed": n_core, "core_substeps_per_s": core["substeps_per_s"],
                "core_substep_us": core["substep_s"] * 1e6, "force_sum": core["force_sum"],
                "bandwidth_bytes_per_s": core["bandwidth_bytes_per_s"],
                "roofline_substep_s": core["roofline_substep_s"],
                "roofline_fraction_streamed": core["roofline_fraction"],
                "roofline_fraction_compulsory": core["roofline_fraction_compulsory"]})
    log.info("%s", rec)
    return rec


def default_variant() -> str:
    ig = TwinConfig().integrator
    return f"{ig.resident_variant}:{ig.resident_coloring}"


def device_name(device: str) -> str:
    d = wp.get_device(device)
    return f"cuda:{d.name}" if d.is_cuda else "cpu"


def main(argv: list[str] | None = None) -> list[dict]:
    # argparse, not a Hydra app (issue 16): a developer measurement outside the results DAG whose
    # flags are sizes, devices and repeats, not experiment config (nothing to compose or sweep)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh-dir", type=Path, default=Path("results/twin"))
    parser.add_argument("--resolutions", nargs="+", default=["coarse", "reference"])
    parser.add_argument("--n-envs", nargs="+", type=int, default=[1, 8, 64, 500])
    parser.add_argument("--device", default="cuda" if wp.is_cuda_available() else "cpu")
    parser.add_argument("--max-frames", type=int, default=SLIDE_FRAMES,
                        help="frames timed per point at most (default: a full slide; fewer -> extrapolated)")
    parser.add_argument("--budget-s", type=float, default=None,
                        help="time fewer frames so each point takes about this long (extrapolated; slow CPUs)")
    parser.add_argument("--kernel", choices=["streamed", "resident", "auto"], default="streamed",
                        help="twin.integrator.kernel: the streamed substep kernels, the frame-resident one, or auto "
                             "(on the CPU: resident, one lane in mesh order)")
    parser.add_argument("--block-dim", type=int, nargs="+", default=[TwinConfig().integrator.block_dim],
                        help="threads per env block of the resident kernel (one record each)")
    parser.add_argument("--variants", nargs="+", default=[default_variant()],
                        help="resident kernel variants, VARIANT or VARIANT:COLORING (twin.integrator."
                             f"resident_variant: {', '.join(RESIDENT_VARIANTS)}; resident_coloring: "
                             f"{', '.join(RESIDENT_COLORINGS)}); one record each")
    parser.add_argument("--layered", action="store_true",
                        help="the residual loop's layered elastic kernel (palpation.twin.agreement.LAYERED)")
    parser.add_argument("--out", type=Path, default=Path("results/bench/twin.json"))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(name)s %(message)s")
    records = []
    for res in args.resolutions:
        mesh = SensorMesh.load(args.mesh_dir / f"mesh_{res}.npz")
        for n in args.n_envs:
            resident = args.kernel == "resident"
            for variant in (args.variants if resident else [default_variant()]):
                for block_dim in (args.block_dim if resident else [None]):
                    cfg = twin_config(LAYERED if args.layered else ())
                    cfg.device = args.device
                    cfg.integrator.kernel = args.kernel
                    cfg.integrator.block_dim = block_dim or cfg.integrator.block_dim
                    name, _, coloring = variant.partition(":")
                    cfg.integrator.resident_variant = name
                    cfg.integrator.resident_coloring = coloring or cfg.integrator.resident_coloring
                    cfg.validate()  # a mistyped --variants fails here with the key to fix
                    records.append(bench_point(mesh, cfg, n, args.device, args.max_frames, args.budget_s))
                    save_json(args.out, records)  # rewritten after each point: a long run keeps what it has
    print(json.dumps(records, indent=1))
    return records


if __name__ == "__main__":
    main()
