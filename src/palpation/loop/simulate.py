"""Final-frame markers of many (state, loop parameters) jobs, batched as twin environments.

Every job is one measured state (kind, depth, angle) under one parameter set. Jobs that differ only
in the camera share one simulated environment (the camera acts at projection), so a batch simulates
each distinct physics once. Per env the mount offset composes the planned schedule (the controller
never sees it), and the markers are projected in numpy from the final node positions with a binding
made through that env's camera (markers.bind_markers_through). On a CPU, kinds run as separate
batches: every env costs the longest env's frames.

Three things make the loop cheaper without changing a byte (an env's result does not depend on the
batch it runs in: the CPU kernels run env after env, each env's sums in its own order):
* a physics cache: an env already simulated (same state, same physics parameters; the search's warm
  starts, each polish chain's base, the evaluation after a polish) is read back instead of re-run;
* `workers` threads: Warp runs a CPU kernel on one core and replays a CPU graph without Python's lock,
  so the batches (each kind's envs cut in `workers` parts) run side by side. Building a twin and
  capturing its graph go through Warp's process-wide capture state: one thread at a time
  (twin.runner.LockedBatch, twin.warp_runtime.run_parts);
* a pool of built twins: a call of as many envs as an earlier one resets that twin, sets its parameters and
  schedule and replays its captured frame graph (twin.simulator.BatchedTwin.set_schedule); building and
  capturing took ~0.18 s a call, 15 s of the paper loop's 88 calls on an H100 (device profile).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np

from palpation.loop.effects import split
from palpation.twin.config import TwinConfig
from palpation.twin.markers import CameraBinding, ImageSimilarity, bind_markers_through, project_markers_np
from palpation.twin.mesh import SensorMesh
from palpation.twin.parameters import PARAMETERS
from palpation.twin.runner import EnvRequest, LockedBatch, plan_requests
from palpation.twin.trajectory import Trajectory, mount_offset, padded_schedule, with_mount
from palpation.twin.warp_runtime import CAPTURE_LOCK, run_parts, usable_cores

log = logging.getLogger(__name__)
IDLE_TWINS = 12  # built twins kept between calls (~1 MB an env reference on the GPU)
CACHE_BYTES = 512 * 2**20  # final node positions kept for re-use (~5 kB an env coarse, ~41 kB reference)


@dataclass(frozen=True)
class State:
    """One interaction state to reproduce (geometry as the twin takes it)."""

    name: str
    kind: str
    depth_mm: float | None = None
    angle_deg: float | None = None
    heading_offset_deg: float = 0.0


Job = tuple[State, Mapping[str, float]]


def loop_twin_config(cfg: TwinConfig, shell_thickness_m: float) -> TwinConfig:
    """The twin the loop varies per env: phantom contact on (k_s = 0 keeps it inert), the layered kernel
    on (ratio 1 and the config's alpha reproduce the reference kernel bit for bit), camera and mount
    nominal in the config because the loop carries them per env."""
    if not cfg.camera.is_identity or not cfg.mount.is_identity or cfg.markers.anchor != 0.0:
        raise ValueError("loop: twin.camera, twin.mount and twin.markers must be nominal; the loop sets them "
                         "per env (cam_*, mount_* and marker_anchor parameters)")
    k_s = cfg.contact.k_s if cfg.contact.phantom_contact else PARAMETERS["k_s"].off  # off until the loop adds it
    c = replace(cfg, contact=replace(cfg.contact, phantom_contact=True, k_s=k_s),
                material=replace(cfg.material, shell_thickness=shell_thickness_m),
                damping=replace(cfg.damping, per_env=True))
    return c.validate()


class LoopSimulator:
    """`simulate(jobs)`: final-frame markers of (state, loop parameters) jobs.

    `workers`: threads running batches side by side (None: the usable cores on a CPU, 1 on CUDA, where
    one batch fills the device); `cache_bytes`: room for final node positions of simulated envs (0: off).
    Neither changes a result (tests/loop/test_simulate.py)."""

    def __init__(self, mesh: SensorMesh, cfg: TwinConfig, template_px: np.ndarray, device: str | None = None,
                 split_by_kind: bool | None = None, max_frames: int | None = None, workers: int | None = None,
                 cache_bytes: int = CACHE_BYTES):
        self.mesh, self.cfg, self.template = mesh, cfg, np.asarray(template_px, np.float64)
        self.device = device or cfg.device
        cpu = str(self.device).startswith("cpu")
        self.split = cpu if split_by_kind is None else bool(split_by_kind)
        self.workers = max(1, int(workers if workers is not None else usable_cores() if cpu else 1))
        self.max_frames = max_frames
        self._bindings: dict[tuple, CameraBinding] = {}
        self._plans: dict[tuple, Trajectory] = {}  # planned schedule per (kind, depth, angle, heading)
        self._cache: OrderedDict[tuple, tuple] = OrderedDict()  # physics key -> (nodes, pose, failed), LRU
        self._cache_room, self._cache_used = int(cache_bytes), 0
        self._twins: list = []  # idle built twins, the most recently used last: a call reuses one of its size
        self._twins_lock = threading.Lock()  # the worker threads take and return them
        self.envs_simulated = 0  # distinct physics simulated so far (for the budget log)
        self.cache_hits = 0  # distinct physics read back from the cache instead
        # env-frames simulated, and their span: per call the env-frames of the worker thread that ran the most
        # (as the pool handed the parts out, longest first), i.e. the twin's wall time in env-frames
        self.env_frames = self.span_frames = self.cached_frames = 0  # cached: the env-frames the cache saved
        self.calls, self.sim_s = 0, 0.0  # twin calls (sequential batches) and the time spent in them

    def binding(self, camera: Mapping[str, float]) -> CameraBinding:
        image = ImageSimilarity(**{k: float(v) for k, v in camera.items()})
        key = (image.f_scale, image.rotation_deg, image.dx_px, image.dy_px)
        if key not in self._bindings:
            self._bindings[key] = bind_markers_through(self.mesh.nodes, self.mesh.dome_nodes, self.template,
                                                       image)
        return self._bindings[key]

    def simulate(self, jobs: list[Job]) -> tuple[np.ndarray, np.ndarray]:
        """(n, 127, 2) float64 pixels (NaN where the env diverged) and (n,) failed flags."""
        if not jobs:
            return np.zeros((0, len(self.template), 2)), np.zeros(0, bool)
        t0 = time.perf_counter()
        try:
            return self._simulate(jobs)
        finally:
            self.calls += 1
            self.sim_s += time.perf_counter() - t0

    def _simulate(self, jobs: list[Job]) -> tuple[np.ndarray, np.ndarray]:
        parts = [split(params) for _, params in jobs]
        physics = [(s.kind, s.depth_mm, s.angle_deg, s.heading_offset_deg, tuple(sorted(env.items())),
                    tuple(sorted(mount.items()))) for (s, _), (env, _, mount, _) in zip(jobs, parts)]
        unique = list(dict.fromkeys(physics))
        results = {key: self._cache[key] for key in unique if key in self._cache}
        for key in results:
            self._cache.move_to_end(key)
        todo = [u for u in unique if u not in results]
        self.cache_hits += len(results)
        self.cached_frames += sum(self._frames(key) for key in results)
        self.envs_simulated += len(todo)
        results.update(self._run_all(todo))
        out = np.full((len(jobs), len(self.template), 2), np.nan)
        bad_out = np.zeros(len(jobs), bool)
        for j, (key, (_, camera, _, markers)) in enumerate(zip(physics, parts)):
            nodes, pose, failed = results[key]
            if failed:
                bad_out[j] = True
                continue
            through = self.binding(camera)
            out[j] = through.markers(project_markers_np(through.binding, nodes[None], pose[None])[0])
            # anchor: move the (nominal) bound rest onto the template, as twin.config.MarkerConfig
            out[j] += markers.get("anchor", 0.0) * (self.template - through.anchor_px)
        return out, bad_out

    def _run_all(self, todo: list[tuple]) -> dict[tuple, tuple]:
        """Simulate the distinct physics `todo` (per kind on a CPU, each cut in `workers` parts run side by
        side, the longest first) and keep them in the cache; returns {key: (nodes, pose, failed)}."""
        groups = [todo] if not self.split else [[u for u in todo if u[0] == k]
                                                for k in dict.fromkeys(u[0] for u in todo)]
        parts = [[g[i] for i in ix] for g in groups if g
                 for ix in np.array_split(np.arange(len(g)), min(self.workers, len(g)))]
        work = [len(p) * self._frames(p[0]) for p in parts]  # env-frames: a part's cost on a CPU
        order = sorted(range(len(parts)), key=lambda i: -work[i])
        parts, work = [parts[i] for i in order], [work[i] for i in order]
        runs, ran_on = run_parts(self._run, parts, self.workers)
        load = np.bincount(ran_on, weights=work, minlength=1)  # env-frames each worker thread really ran
        self.env_frames += sum(work)
        self.span_frames += int(load.max())
        out = {}
        for part, (n_A, T, bad) in zip(parts, runs):
            for i, key in enumerate(part):
                out[key] = (n_A[i].copy(), T[i].copy(), bool(bad[i]))  # not views of the batch
                self._remember(key, out[key])
        return out

    def _plan(self, key: tuple) -> Trajectory:
        """One env's nominal schedule, planned once per geometry: planning is row-wise (a batch plans each env
        as alone, twin.trajectory.plan_trajectories), and re-planning every call cost ~60 ms a call on the
        reference paper loop (device profile)."""
        geometry = key[:4]
        if geometry not in self._plans:
            self._plans[geometry] = plan_requests(self.mesh, self.cfg, [self._request(key)], self.max_frames)[0]
        return self._plans[geometry]

    def _frames(self, key: tuple) -> int:
        """Frames of one env's schedule (set by its kind and geometry)."""
        return self._plan(key).n_frames

    def _request(self, key: tuple) -> EnvRequest:
        """The twin request of one distinct physics key (kind, depth, angle, heading, params, mount)."""
        kind, d, a, h, params, _ = key
        return EnvRequest(kind, h, depth_mm=d, angle_deg=a, record="last", **dict(params)).resolved(self.cfg)

    def _remember(self, key: tuple, value: tuple) -> None:
        size = value[0].nbytes + value[1].nbytes
        if size > self._cache_room:
            return
        self._cache[key] = value
        self._cache_used += size
        while self._cache_used > self._cache_room:  # the least recently used go first
            _, (n, T, _) = self._cache.popitem(last=False)
            self._cache_used -= n.nbytes + T.nbytes

    def _take_twin(self, n_envs: int):
        """The most recently used idle twin built for `n_envs` envs, or None (LockedBatch builds one)."""
        with self._twins_lock:
            for i in range(len(self._twins) - 1, -1, -1):
                if self._twins[i].n_envs == n_envs:
                    return self._twins.pop(i)
        return None

    def _keep_twin(self, twin) -> None:
        """Keep a twin for a later call of its size; past IDLE_TWINS the least recently used goes (freed
        under the capture lock, like every twin, warp_runtime.CAPTURE_LOCK)."""
        with self._twins_lock:
            self._twins.append(twin)
            cut = max(0, len(self._twins) - IDLE_TWINS)
            evicted, self._twins = self._twins[:cut], self._twins[cut:]
        with CAPTURE_LOCK:
            del evicted

    def _run(self, group: list[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Simulate distinct physics to their last frame: final nodes (n, N, 3), poses, failed flags."""
        reqs = [self._request(key) for key in group]
        trajs = [self._plan(key) for key in group]
        trajs = [with_mount(t, mount_offset(**{"dz_m" if k == "dz" else k: v for k, v in mount}))
                 if mount else t for t, (*_, mount) in zip(trajs, group)]
        schedule, lengths = padded_schedule(trajs)
        nodes = np.full((len(group), self.mesh.n_nodes, 3), np.nan, np.float32)
        failed = np.zeros(len(group), bool)
        ends = {int(e) - 1 for e in lengths}
        twin = self._take_twin(len(group))
        with LockedBatch(self.mesh, self.cfg, reqs, trajs, schedule, self.device, twin=twin) as run:
            for f in run:
                if f in ends:  # read only where some env ends; the failure flag is sticky
                    done = lengths - 1 == f
                    nodes[done], failed[done] = run.read(lambda sim, _: (sim.positions_world()[done],
                                                                         sim.failed()[done]))
            self._keep_twin(run.twin)
        T_last = np.stack([t.T_BA[-1] for t in trajs])
        return nodes, T_last, failed | ~np.all(np.isfinite(nodes), axis=(1, 2))
