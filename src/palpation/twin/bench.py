"""Micro-benchmark of the FEM substep and its memory-bandwidth roofline (the FEM core only).

The trajectory benchmark (runner, markers, I/O) calls `time_substeps` for the bare-core figures.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from palpation.twin.config import TwinConfig
from palpation.twin.mesh import SensorMesh
from palpation.twin.simulator import BatchedTwin

# peak DRAM bandwidth (bytes/s) by device-name substring, for the roofline fraction
PEAK_BANDWIDTH = {"H200": 4.8e12, "H100 PCIe": 2.0e12, "H100": 3.35e12, "A100": 1.9e12,
                  "RTX 3080": 7.6e11}
VEC3, I32, F32, MAT33 = 12, 4, 4, 36


def substep_bytes(n_nodes: int, n_tets: int, n_surface: int, n_envs: int,
                  gather: bool = False) -> dict[str, int]:
    """DRAM bytes of one substep, as streamed (every access) and compulsory (each array once).

    A substep is the elastic pass over `n_tets` (the tets that move) and one fused node pass
    (contact, integration, control). Scatter: 4 float atomics (read + write) per tet into f, which
    the node pass reads and clears. Gather: 4 contiguous stores per tet, which the node pass reads
    once each through an index list.
    """
    sink = 4 * VEC3 + 4 * (VEC3 + I32) if gather else 4 * 2 * VEC3  # stores + indexed reads, or atomics
    tet_stream = 4 * I32 + MAT33 + 4 * 2 * VEC3 + sink  # idx, Dm^-1, x+v gathers, corner forces
    node_stream = (2 * 2 * VEC3 + VEC3 + F32 + 3 * I32  # x, v r+w; v_ctl; 1/m; fixed, surface, slots
                   + (0 if gather else 2 * VEC3))  # scatter: f read and cleared
    surf_stream = VEC3  # write f_c
    streamed = n_envs * (n_tets * tet_stream + n_nodes * node_stream + n_surface * surf_stream)
    # compulsory: connectivity and Dm^-1 once (shared); per env x, v read + written, v_ctl read,
    # f_c written (the forces between the passes could stay on chip)
    compulsory = n_tets * (4 * I32 + MAT33) + n_envs * (n_nodes * (2 * 2 * VEC3 + VEC3)
                                                        + n_surface * VEC3)
    return {"streamed": int(streamed), "compulsory": int(compulsory)}


def resident_substep_bytes(n_nodes: int, n_tets: int, n_surface: int, n_fixed: int, n_envs: int,
                           substeps: int, packed: bool = False) -> dict[str, int]:
    """Global-memory bytes per substep of the frame-resident kernel (twin/resident.py).

    Per env and substep a block reads the mesh constants (tet indices, Dm^-1, 1/m and the node
    masks: the same for every env, so L2 hits) and v_control of its driven nodes; once per frame it
    loads and stores x, v and writes f_c of the surface nodes. "streamed" counts every access,
    "compulsory" each array once per frame (mesh constants once per batch), both per substep.
    `packed` (resident_variant packed/atomic/compact): the 4 corner indices in one 8-byte word.
    """
    mesh_const = n_tets * ((8 if packed else 4 * I32) + MAT33) + n_nodes * (F32 + 3 * I32)
    per_frame = n_nodes * 4 * VEC3 + n_surface * VEC3  # x, v in and out; f_c
    streamed = n_envs * (mesh_const + n_fixed * VEC3 + per_frame / substeps)
    compulsory = mesh_const / substeps + n_envs * (per_frame + n_nodes * VEC3) / substeps  # + v_control
    return {"streamed": int(streamed), "compulsory": int(compulsory)}


def measure_host_bandwidth(n_bytes: int = 1 << 27) -> float:
    """Copy bandwidth of this host (bytes/s read + written) from a numpy copy."""
    a, b = np.ones(n_bytes // 8), np.empty(n_bytes // 8)
    np.copyto(b, a)
    t = time.perf_counter()
    for _ in range(3):
        np.copyto(b, a)
    return 3 * 2 * a.nbytes / (time.perf_counter() - t)


def device_bandwidth(device) -> float:
    device = wp.get_device(device)
    if device.is_cpu:
        return measure_host_bandwidth()
    for key, bw in PEAK_BANDWIDTH.items():
        if key in device.name:
            return bw
    return float("nan")


def time_substeps(mesh: SensorMesh, n_envs: int, n_substeps: int = 124, device: str = "cpu",
                  cfg: TwinConfig | None = None, repeats: int = 3) -> dict:
    """Substeps per second of `n_envs` envs over one frame of `n_substeps` (graph replay on CUDA).

    The sensor sits at rest far from the vessel; the cost of a substep does not depend on the state.
    """
    cfg = cfg or TwinConfig()
    cfg.integrator.substeps = n_substeps
    sim = BatchedTwin(mesh, n_envs, cfg, device=device)
    T = np.tile(np.eye(4), (n_envs, 1, 1))
    T[:, :3, 3] = [0.0, 0.0, 0.1]
    sim.reset(T)
    sim.step_frame(T)  # compile, capture the graph, warm caches
    wp.synchronize_device(sim.device)
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        sim.step_frame(T)
        wp.synchronize_device(sim.device)
        best = min(best, time.perf_counter() - t)
    per_substep = best / n_substeps
    if sim.resident is not None:
        nbytes = resident_substep_bytes(mesh.n_nodes, sim.n_force_tets, len(mesh.surface_nodes),
                                        int(mesh.fixed.sum()), n_envs, n_substeps,
                                        packed=sim.resident.variant not in ("tiles", "onesync"))
    else:
        nbytes = substep_bytes(mesh.n_nodes, sim.n_force_tets, len(mesh.surface_nodes), n_envs, sim.gather)
    bw = device_bandwidth(sim.device)
    force_sum = "colored" if sim.resident is not None else "gather" if sim.gather else "scatter"
    return {"device": str(sim.device), "device_name": sim.device.name, "resolution": mesh.resolution,
            "n_envs": n_envs, "n_substeps": n_substeps, "force_sum": force_sum,
            "substeps_per_s": 1.0 / per_substep,
            "env_substeps_per_s": n_envs / per_substep, "substep_s": per_substep,
            "bytes_streamed": nbytes["streamed"], "bytes_compulsory": nbytes["compulsory"],
            "bandwidth_bytes_per_s": bw, "roofline_substep_s": nbytes["streamed"] / bw,
            "roofline_fraction": nbytes["streamed"] / bw / per_substep,
            "roofline_fraction_compulsory": nbytes["compulsory"] / bw / per_substep}


def is_stable(mesh: SensorMesh, cfg: TwinConfig, n_substeps: int = 3000, device: str = "cpu",
              seed: int = 0) -> bool:
    """Does a 1 um random perturbation of the free nodes stay bounded over n_substeps of cfg.dt?"""
    cfg.integrator.substeps, cfg.integrator.zero_velocity_each_frame = n_substeps, False
    sim = BatchedTwin(mesh, 1, cfg, device=device)
    sim.reset(np.eye(4)[None])
    noise = np.random.default_rng(seed).normal(0.0, 1e-6, mesh.nodes.shape) * ~mesh.fixed[:, None]
    sim.x.assign((mesh.nodes + noise).astype(np.float32))
    sim.step_frame(np.eye(4)[None])
    dev = sim.positions_world()[0] - sim.undeformed_world()[0]
    return bool(np.all(np.isfinite(dev)) and np.abs(dev).max() < 1e-4)


def stable_dt(mesh: SensorMesh, cfg: TwinConfig | None = None, lo: float = 1e-7, hi: float = 1e-4,
              rel_tol: float = 0.03, **kwargs) -> float:
    """Largest stable substep (bisection on `is_stable`, geometric midpoints)."""
    cfg = cfg or TwinConfig()
    while hi / lo > 1.0 + rel_tol:
        mid = float(np.sqrt(lo * hi))
        cfg.integrator.dt = mid
        lo, hi = (mid, hi) if is_stable(mesh, cfg, **kwargs) else (lo, mid)
    return lo


if __name__ == "__main__":
    import argparse
    import json

    from palpation.twin.mesh import build_sensor_mesh

    # argparse, not a Hydra app (issue 16): a developer measurement outside the results DAG whose
    # flags are sizes, devices and repeats, not experiment config (nothing to compose or sweep)
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--resolution", default="coarse")
    parser.add_argument("--envs", type=int, nargs="+", default=[1, 8, 64])
    parser.add_argument("--substeps", type=int, default=124)
    args = parser.parse_args()
    mesh = build_sensor_mesh(args.resolution)
    with wp.ScopedDevice(args.device):
        for n in args.envs:
            print(json.dumps(time_substeps(mesh, n, args.substeps, args.device)))
