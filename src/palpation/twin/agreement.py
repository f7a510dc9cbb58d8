"""CPU vs CUDA agreement of the twin: the same batch on both devices, marker differences in px.

GPU atomics add forces in a nondeterministic order, so the devices agree only to float32 rounding
amplified over a trajectory (the reference replays to ~0.04 px). This script measures the figure.

    python -m palpation.twin.agreement --mesh results/twin/mesh_coarse.npz --out results/bench/agreement.json
    python -m palpation.twin.agreement --mesh results/twin/mesh_reference.npz --devices cuda:0 \
        --kernels streamed resident --out results/bench/agreement_resident.json   # issue 17
"""

from __future__ import annotations

import argparse
import logging
import sys

import numpy as np

from palpation.io import save_json
from palpation.tracking import git_commit
from palpation.twin.config import TwinConfig
from palpation.twin.markers import bind_markers
from palpation.twin.mesh import SensorMesh
from palpation.twin.runner import EnvRequest, run_batch

log = logging.getLogger(__name__)


def agreement_requests() -> list[EnvRequest]:
    """Every canonical interaction vessel-free plus a vessel slide (contact exercised)."""
    reqs = [EnvRequest(kind=k, name=k) for k in ("press", "twist_z", "twist_x", "slide")]
    reqs.append(EnvRequest(kind="slide", vessel=True, heading_offset_deg=8.22, name="vessel_slide"))
    return reqs


def compare_devices(mesh: SensorMesh, devices: list[str], max_frames: int | None = None,
                    kernels: tuple[str, str] = ("streamed", "streamed"), variant: str | None = None,
                    block_dim: int | None = None) -> dict:
    """The agreement batch on devices[0] with kernels[0] vs devices[-1] with kernels[-1];
    `variant` ("VARIANT" or "VARIANT:COLORING") and `block_dim` set the resident runs' integrator keys."""
    from palpation.markers.template import rest_template

    binding = bind_markers(mesh.nodes, mesh.dome_nodes, rest_template())
    runs = []
    for dev, kernel in ((devices[0], kernels[0]), (devices[-1], kernels[-1])):
        cfg = TwinConfig()
        cfg.integrator.kernel = kernel
        if variant:
            name, _, coloring = variant.partition(":")
            cfg.integrator.resident_variant = name
            cfg.integrator.resident_coloring = coloring or cfg.integrator.resident_coloring
        cfg.integrator.block_dim = block_dim or cfg.integrator.block_dim
        res = run_batch(mesh, cfg, agreement_requests(), binding=binding, device=dev, progress=False,
                        max_frames=max_frames)
        if res.failed:
            raise RuntimeError(f"{dev} ({kernel}): envs failed: {[f.name for f in res.failed]}")
        runs.append({r.name: r for r in res.records})
    per = {}
    for name, rec in runs[0].items():
        diff = np.linalg.norm(rec.markers.astype(np.float64) - runs[1][name].markers, axis=-1)
        contact_same = float(np.mean(rec.contact == runs[1][name].contact))
        per[name] = {"max_px": float(diff.max()), "mean_px": float(diff.mean()),
                     "final_mean_px": float(diff[-1].mean()), "contact_agreement": contact_same}
    ig = cfg.integrator  # the last run's: the resident one if any
    return {"devices": devices, "kernels": list(kernels), "resident_variant": f"{ig.resident_variant}:"
            f"{ig.resident_coloring}", "block_dim": ig.block_dim, "resolution": mesh.resolution, "commit": git_commit(),
            "frames": {name: len(rec.markers) for name, rec in runs[0].items()},
            "max_px": max(v["max_px"] for v in per.values()), "per_trajectory": per}


def main(argv: list[str] | None = None) -> int:
    # argparse, not a Hydra app (issue 16): a developer measurement outside the results DAG whose
    # flags are sizes, devices and repeats, not experiment config (nothing to compose or sweep)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", required=True, help="cached mesh npz (rule `mesh`)")
    parser.add_argument("--devices", nargs="+", default=["cpu", "cuda:0"],
                        help="first is the reference (default: cpu cuda:0)")
    parser.add_argument("--kernels", nargs="+", default=["streamed"], choices=["streamed", "resident"],
                        help="twin.integrator.kernel of the first and the last run (default: streamed both)")
    parser.add_argument("--variant", default=None,
                        help="resident runs: twin.integrator.resident_variant[:resident_coloring], e.g. packed")
    parser.add_argument("--block-dim", type=int, default=None, help="resident runs: twin.integrator.block_dim")
    parser.add_argument("--max-frames", type=int, default=None, help="cut trajectories short")
    parser.add_argument("--out", required=True, help="JSON output")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO)
    kernels = (args.kernels[0], args.kernels[-1])
    result = compare_devices(SensorMesh.load(args.mesh), args.devices, args.max_frames, kernels, args.variant,
                             args.block_dim)
    save_json(args.out, result)
    print(f"max marker difference {args.devices[0]} {kernels[0]} vs {args.devices[-1]} {kernels[1]} "
          f"({result['resident_variant'] + '@' + str(result['block_dim']) if 'resident' in kernels else 'streamed'}): "
          f"{result['max_px']:.4g} px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
