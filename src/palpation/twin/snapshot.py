"""Run a batch until each env meets a stop rule and keep one snapshot per env (calibration).

`run_batch` records fixed frame windows; the reference calibration instead stops a slide on the
first frame whose projected vessel centreline comes within 55 px of the marker centroid (SPEC §6.2)
and reads node heights there. As runner.ScheduledBatch steps the schedule, this loop reads the node
positions every frame (markers are projected in numpy, as the trigger needs them on the host anyway),
asks `stop` which active envs are done, and keeps their markers, nodes and pose. An env also stops at
its `last_frame`; a finished schedule holds its last pose, so `last_frame` may lie past the
trajectory's end (the reference caps a triggered slide at 400 frames while the slide itself has 398).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import warp as wp

from palpation.twin.config import TwinConfig
from palpation.twin.markers import MarkerBinding, bind_markers, project_markers_np
from palpation.twin.mesh import SensorMesh
from palpation.twin.warp_runtime import init_warp
from palpation.twin.runner import EnvRequest, ScheduledBatch, plan_requests

# stop(frame, markers (n, 127, 2) px, T_BA (n, 4, 4)) -> (n,) bool: stop these envs at this frame
StopRule = Callable[[int, np.ndarray, np.ndarray], np.ndarray]


@dataclass
class Snapshots:
    frame: np.ndarray  # (n,) frame index of each snapshot; -1 where the env failed first
    markers: np.ndarray  # (n, 127, 2) float64 px; NaN where failed
    nodes_A: np.ndarray  # (n, N, 3) float32 world positions, metres; NaN where failed
    T_BA: np.ndarray  # (n, 4, 4) pose at the snapshot
    failed: np.ndarray  # (n,) bool: diverged or inverted before its snapshot
    stopped_by_rule: np.ndarray  # (n,) bool: `stop` fired (False: reached last_frame)
    frames: int  # frames simulated (the longest env)
    wall_s: float


def run_until(mesh: SensorMesh, cfg: TwinConfig, requests: list[EnvRequest], stop: StopRule | None = None,
              last_frame: np.ndarray | None = None, binding: MarkerBinding | None = None,
              device: str | None = None, max_frames: int | None = None, progress: bool = False) -> Snapshots:
    """Simulate until every env stopped (rule or `last_frame`, default its trajectory's last frame)."""
    if not requests:
        raise ValueError("run_until needs at least one EnvRequest")
    init_warp()
    device = wp.get_device(device or cfg.device)
    if binding is None:
        from palpation.markers.template import rest_template
        binding = bind_markers(mesh.nodes, mesh.dome_nodes, rest_template())
    reqs = [r.resolved(cfg) for r in requests]
    trajs = plan_requests(mesh, cfg, reqs, max_frames)
    n = len(reqs)
    last = np.array([t.n_frames - 1 for t in trajs]) if last_frame is None else np.asarray(last_frame, int)
    if last.shape != (n,) or np.any(last < 0):
        raise ValueError(f"last_frame must hold one frame index >= 0 per env ({n}), got {last_frame}")
    n_frames = int(last.max()) + 1
    schedule = np.empty((n_frames, n, 4, 4))
    for i, t in enumerate(trajs):  # hold the last pose past the trajectory's end
        k = min(t.n_frames, n_frames)
        schedule[:k, i] = t.T_BA[:k]
        schedule[k:, i] = t.T_BA[-1]

    start = time.perf_counter()
    batch = ScheduledBatch(mesh, cfg, reqs, trajs, schedule, device)
    sim = batch.sim
    out = Snapshots(frame=np.full(n, -1), markers=np.full((n, len(binding.node_ix), 2), np.nan),
                    nodes_A=np.full((n, mesh.n_nodes, 3), np.nan, np.float32),
                    T_BA=np.full((n, 4, 4), np.nan), failed=np.zeros(n, bool),
                    stopped_by_rule=np.zeros(n, bool), frames=0, wall_s=0.0)
    active = np.ones(n, bool)
    for f in batch.frames(progress=progress):
        bad = sim.failed() & active
        out.failed |= bad
        active &= ~bad
        nodes = sim.positions_world()
        markers = project_markers_np(binding, nodes, schedule[f])
        fired = np.asarray(stop(f, markers, schedule[f]), bool) if stop is not None else np.zeros(n, bool)
        done = active & (fired | (f >= last))
        out.frame[done], out.markers[done] = f, markers[done]
        out.nodes_A[done], out.T_BA[done] = nodes[done], schedule[f][done]
        out.stopped_by_rule |= done & fired
        active &= ~done
        out.frames = f + 1
        if not active.any():
            break
    out.wall_s = time.perf_counter() - start
    return out
