"""CPU vs CUDA agreement of the twin: the same batch on both devices, marker differences in px.

GPU atomics add forces in a nondeterministic order, so the devices agree only to float32 rounding
amplified over a trajectory (the reference replays to ~0.04 px). This script measures the figure.

    python -m palpation.twin.agreement --mesh results/twin/mesh_coarse.npz --out results/bench/agreement.json
    python -m palpation.twin.agreement --mesh results/twin/mesh_reference.npz --devices cuda:0 \
        --kernels streamed resident --out results/bench/agreement_resident.json   # issue 17
    ... --kernels streamed resident --layered     # the residual loop's layered elastic kernel (LAYERED)
    ... --set contact.k_n=20 damping.alpha=0.05    # any twin config keys, both runs
"""

from __future__ import annotations

import argparse
import logging
import sys

import numpy as np

from omegaconf import OmegaConf

from palpation.io import save_json
from palpation.tracking import git_commit
from palpation.twin.config import KERNELS, TwinConfig
from palpation.twin.markers import bind_markers
from palpation.twin.mesh import SensorMesh
from palpation.twin.runner import EnvRequest, run_batch

log = logging.getLogger(__name__)

# --layered: the residual loop's layered elastic kernel (loop.simulate.loop_twin_config: a 1.5 mm shell, per-env
# alpha), with a 1.5x stiffer shell (1.3 MPa: the reference mesh is stable to ~1.47 MPa at dt = 1e-5 s; 3x diverges
# there) and phantom contact at k_s = 2000 N/m so that every trajectory presses on it
LAYERED = ("material.shell_thickness=0.0015", "material.shell_ratio=1.5", "damping.per_env=true",
           "contact.phantom_contact=true", "contact.k_s=2000.0")


def twin_config(overrides=()) -> TwinConfig:
    """TwinConfig() with dotted `KEY=VALUE` overrides (twin config keys, typed and checked by OmegaConf)."""
    node = OmegaConf.structured(TwinConfig)
    try:
        node.merge_with_dotlist(list(overrides))
    except Exception as exc:  # omegaconf: unknown key or a value of the wrong type
        raise ValueError(f"agreement --set {' '.join(overrides)}: {str(exc).splitlines()[0]}") from None
    return OmegaConf.to_object(node)


def agreement_requests() -> list[EnvRequest]:
    """Every canonical interaction vessel-free plus a vessel slide (contact exercised)."""
    reqs = [EnvRequest(kind=k, name=k) for k in ("press", "twist_z", "twist_x", "slide")]
    reqs.append(EnvRequest(kind="slide", vessel=True, heading_offset_deg=8.22, name="vessel_slide"))
    return reqs


def compare_devices(mesh: SensorMesh, devices: list[str], max_frames: int | None = None,
                    kernels: tuple[str, str] = ("streamed", "streamed"), variant: str | None = None,
                    block_dim: int | None = None, overrides=()) -> dict:
    """The agreement batch on devices[0] with kernels[0] vs devices[-1] with kernels[-1];
    `variant` ("VARIANT" or "VARIANT:COLORING") and `block_dim` set the resident runs' integrator keys,
    `overrides` (KEY=VALUE twin config keys, e.g. LAYERED) both runs' config."""
    from palpation.markers.template import rest_template

    binding = bind_markers(mesh.nodes, mesh.dome_nodes, rest_template())
    runs = []
    for dev, kernel in ((devices[0], kernels[0]), (devices[-1], kernels[-1])):
        cfg = twin_config(overrides)
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
            "overrides": list(overrides), "layered": cfg.layered,
            "frames": {name: len(rec.markers) for name, rec in runs[0].items()},
            "max_px": max(v["max_px"] for v in per.values()), "per_trajectory": per}


def main(argv: list[str] | None = None) -> int:
    # argparse, not a Hydra app (issue 16): a developer measurement outside the results DAG whose
    # flags are sizes, devices and repeats, not experiment config (nothing to compose or sweep)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", required=True, help="cached mesh npz (rule `mesh`)")
    parser.add_argument("--devices", nargs="+", default=["cpu", "cuda:0"],
                        help="first is the reference (default: cpu cuda:0)")
    parser.add_argument("--kernels", nargs="+", default=["streamed"], choices=list(KERNELS),
                        help="twin.integrator.kernel of the first and the last run (default: streamed both)")
    parser.add_argument("--variant", default=None,
                        help="resident runs: twin.integrator.resident_variant[:resident_coloring], e.g. packed")
    parser.add_argument("--block-dim", type=int, default=None, help="resident runs: twin.integrator.block_dim")
    parser.add_argument("--max-frames", type=int, default=None, help="cut trajectories short")
    parser.add_argument("--layered", action="store_true",
                        help=f"the residual loop's layered elastic kernel, both runs: --set {' '.join(LAYERED)}")
    parser.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                        help="twin config overrides for both runs (after --layered's), e.g. contact.k_n=20")
    parser.add_argument("--out", required=True, help="JSON output")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO)
    kernels = (args.kernels[0], args.kernels[-1])
    overrides = (*(LAYERED if args.layered else ()), *args.set)
    twin_config(overrides).validate()  # a bad key or value fails before the mesh is loaded
    result = compare_devices(SensorMesh.load(args.mesh), args.devices, args.max_frames, kernels, args.variant,
                             args.block_dim, overrides)
    save_json(args.out, result)
    print(f"max marker difference {args.devices[0]} {kernels[0]} vs {args.devices[-1]} {kernels[1]} "
          f"({result['resident_variant'] + '@' + str(result['block_dim']) if set(kernels) != {'streamed'} else 'streamed'}"
          f"{', layered' if result['layered'] else ''}): "
          f"{result['max_px']:.4g} px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
