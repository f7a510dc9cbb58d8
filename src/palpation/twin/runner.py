"""Run a batch of trajectories through `BatchedTwin`, extracting markers every recorded frame.

Each env has its own interaction, heading and contact/material parameters. All pose schedules are
planned up front (the controller only reads the kinematic copy) and padded to the longest: an env
that has finished holds its last pose and records nothing more. Markers and the vessel centreline
are projected on the device every frame into per-env windows (SPEC quirk 6 fixed), and copied to the
host once at the end. The whole schedule is uploaded once; a frame is one graph launch (physics,
contact-flag record, markers), and only the failure flags are read, every READ_FAILED_EVERY frames.
"""

from __future__ import annotations

import logging
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
import warp as wp

from palpation.progress import bar
from palpation.twin.config import TwinConfig
from palpation.twin.contact import record_contact_flags
from palpation.twin.markers import (ImageSimilarity, MarkerBinding, MarkerProjector, bind_markers,
                                    bind_markers_through, centreline_A, marker_labels)
from palpation.twin.mesh import SensorMesh
from palpation.twin.output import FailedRecord, TrajectoryRecord
from palpation.twin.parameters import by_env_key, per_env_keys
from palpation.twin.simulator import BatchedTwin
from palpation.twin.trajectory import (Trajectory, mount_offset, padded_schedule, plan_trajectories, waypoints,
                                       with_mount)
from palpation.twin.warp_runtime import CAPTURE_LOCK, init_warp, resolve_device, run_parts, usable_cores

log = logging.getLogger(__name__)
READ_FAILED_EVERY = 20  # frames between host reads of the failure flags (the reference's interval)


GEOMETRY_KEYS = ("heading_offset_deg", "depth_mm", "angle_deg")


@dataclass(init=False)
class EnvRequest:
    """One environment of a batch: an interaction, its geometry and its per-env twin parameters.

    `twin` holds registry parameters (twin.parameters.per_env_keys, in their units), passed as keywords
    (`EnvRequest("press", E=6e5)`) and readable as attributes (`req.E`); one left out comes from the
    config. depth_mm / angle_deg left None are SPEC's canonical geometry (twin.trajectory.geometry).
    """

    kind: str
    heading_offset_deg: float
    vessel: bool
    seed: int
    name: str
    record: str  # "trajectory": the SPEC window; "last": the last frame only
    depth_mm: float | None  # final tip depth below the phantom top; None = canonical
    angle_deg: float | None  # twist angle; None = canonical (twist_z: 30 deg)
    twin: dict

    def __init__(self, kind: str, heading_offset_deg: float = 0.0, *, vessel: bool = False, seed: int = 0,
                 name: str = "", record: str = "trajectory", depth_mm: float | None = None,
                 angle_deg: float | None = None, **twin: float | None):
        unknown = set(twin) - set(per_env_keys())
        if unknown:
            raise ValueError(f"EnvRequest: unknown twin parameter(s) {sorted(unknown)}; use {per_env_keys()} "
                             "(palpation.twin.parameters)")
        self.kind, self.heading_offset_deg, self.vessel, self.seed = kind, heading_offset_deg, vessel, seed
        self.name, self.record, self.depth_mm, self.angle_deg = name, record, depth_mm, angle_deg
        self.twin = {k: v for k, v in twin.items() if v is not None}

    def __getattr__(self, key: str):
        if key in per_env_keys():  # a twin parameter not set (None = from the config)
            return self.__dict__.get("twin", {}).get(key)
        raise AttributeError(f"'EnvRequest' object has no attribute '{key}'")

    def resolved(self, cfg: TwinConfig) -> "EnvRequest":
        """A copy with every per-env parameter this twin takes filled from the config (geometry as given)."""
        defaults = {k: by_env_key(k).default(cfg) for k in per_env_keys(cfg.layered)}
        return EnvRequest(self.kind, self.heading_offset_deg, vessel=self.vessel, seed=self.seed, name=self.name,
                          record=self.record, depth_mm=self.depth_mm, angle_deg=self.angle_deg,
                          **{**defaults, **self.twin})

    def twin_params(self) -> dict:
        """The JSON-able parameters a record keeps (after `resolved`)."""
        return {**self.twin, "vessel": self.vessel, "heading_offset_deg": self.heading_offset_deg,
                "depth_mm": self.depth_mm, "angle_deg": self.angle_deg}


@dataclass
class BatchResult:
    records: list[TrajectoryRecord]
    failed: list[FailedRecord]
    frames: int  # simulated frames (the longest env)
    wall_s: float
    failed_mask: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))


class ScheduledBatch:
    """The one loop that runs a BatchedTwin batch (run_batch, snapshot.run_until, loop.simulate).

    Builds the twin from resolved requests, poses every env at its trajectory's start, uploads the
    whole (frames, n, 4, 4) schedule and replays one graph per frame; `frames` yields after each so
    the caller reads what it needs (sparse failure flags, a stop rule, final nodes).
    """

    def __init__(self, mesh: SensorMesh, cfg: TwinConfig, requests: list[EnvRequest], trajs: list[Trajectory],
                 schedule: np.ndarray, device, twin: BatchedTwin | None = None):
        self.schedule = schedule
        if twin is None:
            self.sim = BatchedTwin(mesh, len(requests), cfg, env_params(requests), device=device)
        else:  # a twin of an earlier batch, built from the same mesh and config for as many envs
            self.sim = twin
            twin.set_env_params(env_params(requests))
        self.sim.reset(np.stack([t.T_BA0 for t in trajs]))

    def frames(self, extra=None, progress: bool = False):
        """Step the schedule frame by frame, yielding each frame index once it is simulated.

        `extra(frame_index, offset)` launches kernels captured after each frame's physics
        (BatchedTwin.set_schedule)."""
        self.sim.set_schedule(self.schedule, extra)
        for f in bar(range(len(self.schedule)), desc=f"twin x{self.sim.n_envs}", unit="frame", enabled=progress,
                     leave=False):
            self.sim.step_scheduled()  # one graph launch
            yield f


class LockedBatch:
    """A ScheduledBatch run beside other threads' twins: the one owner of the thread protocol (run_batch and
    loop.simulate use it; warp_runtime.CAPTURE_LOCK says why).

    `with LockedBatch(mesh, cfg, requests, trajs, schedule, device, outputs, extra) as run:` builds the twin,
    `outputs(sim)` (device arrays the frames write) and uploads the schedule under the lock, capturing the first
    frame's graph there; `for f in run` yields each frame index, the rest replayed outside the lock; `run.read(fn)`
    returns fn(sim, outputs) read under it; leaving frees every Warp array under it (nothing else may hold them).
    `extra(sim, outputs, frame_index, offset)` launches kernels captured after each frame's physics. `twin`: an
    earlier batch's `run.twin` (same mesh, config, env count) to run on instead of building one; without extra
    kernels it also keeps its captured graph (loop.simulate's pool).
    """

    def __init__(self, mesh: SensorMesh, cfg: TwinConfig, requests: list[EnvRequest], trajs: list[Trajectory],
                 schedule: np.ndarray, device, outputs=None, extra=None, progress: bool = False,
                 twin: BatchedTwin | None = None):
        self._build = (mesh, cfg, requests, trajs, schedule, device, twin)
        self._outputs, self._extra, self._progress = outputs, extra, progress

    def __enter__(self) -> "LockedBatch":
        with CAPTURE_LOCK:
            self._batch = ScheduledBatch(*self._build)
            self._held = self._outputs(self._batch.sim) if self._outputs else None
            extra = None
            if self._extra is not None:  # reaches the twin through self: leaving cuts the cycle, no GC needed
                def extra(frame_index, offset):
                    self._extra(self._batch.sim, self._held, frame_index, offset)
            self._frames = self._batch.frames(extra, self._progress)
            self._first = next(self._frames)
        return self

    def __iter__(self):
        yield self._first
        yield from self._frames  # outside the lock: Warp replays a CPU graph without Python's lock

    def read(self, fn):
        with CAPTURE_LOCK:
            return fn(self._batch.sim, self._held)

    @property
    def twin(self) -> BatchedTwin:
        return self._batch.sim

    def __exit__(self, *exc) -> None:
        with CAPTURE_LOCK:  # Warp arrays freed outside any other thread's capture
            del self._frames, self._batch, self._held


def tip_node_B(mesh: SensorMesh) -> np.ndarray:
    """The undeformed tip the controller tracks: the highest node in B (and in E)."""
    return mesh.nodes[np.argmax(mesh.nodes[:, 2])]


def env_params(requests: list[EnvRequest]) -> dict[str, np.ndarray]:
    """Per-env arrays for BatchedTwin from resolved requests (all resolved against one config)."""
    out = {k: np.array([r.twin[k] for r in requests], np.float64) for k in requests[0].twin}
    out["vessel"] = np.array([r.vessel for r in requests], bool)
    return out


def plan_requests(mesh: SensorMesh, cfg: TwinConfig, requests: list[EnvRequest],
                  max_frames: int | None = None) -> list[Trajectory]:
    """The pose schedule of each (resolved) request, cut to `max_frames` if given.

    A mount offset in the config (cfg.mount, residual loop) moves the sensor off the commanded poses."""
    tip_B = tip_node_B(mesh)
    specs = [(r.kind, r.heading_offset_deg, r.depth_mm, r.angle_deg) for r in requests]
    trajs = [truncate(t, max_frames) for t in plan_trajectories(specs, tip_B, cfg.frame_dt)]  # all in lockstep
    if not cfg.mount.is_identity:
        T_m = mount_offset(cfg.mount.dz, cfg.mount.tilt_x_deg, cfg.mount.tilt_y_deg)
        trajs = [with_mount(t, T_m) for t in trajs]
    return trajs


def record_windows(trajs: list[Trajectory], requests: list[EnvRequest]) -> tuple[np.ndarray, np.ndarray]:
    """Per env [first, end) frames to record."""
    end = np.array([t.n_frames for t in trajs])
    first = np.array([t.record_from if r.record == "trajectory" else t.n_frames - 1
                      for t, r in zip(trajs, requests)])
    if any(r.record not in ("trajectory", "last") for r in requests):
        raise ValueError("EnvRequest.record must be 'trajectory' or 'last'")
    return first, end


def truncate(traj: Trajectory, max_frames: int | None) -> Trajectory:
    """The first `max_frames` frames (smoke tests, benchmarks); the window start moves in if needed."""
    if max_frames is None or traj.n_frames <= max_frames:
        return traj
    if max_frames < 1:
        raise ValueError(f"max_frames must be >= 1, got {max_frames}")
    return replace(traj, T_BA=traj.T_BA[:max_frames], record_from=min(traj.record_from, max_frames - 1))


def run_batch(mesh: SensorMesh, cfg: TwinConfig, requests: list[EnvRequest],
              binding: MarkerBinding | None = None, device: str | None = None, progress: bool = True,
              max_frames: int | None = None) -> BatchResult:
    """Simulate every request as one batch; failed envs come back in `failed`, never as records.

    `max_frames` cuts every schedule short (for smoke tests and timing only).
    """
    if not requests:
        raise ValueError("run_batch needs at least one EnvRequest")
    init_warp()
    device = wp.get_device(device or cfg.device)
    image = ImageSimilarity.from_config(cfg.camera)  # camera error (residual loop); identity by default
    if binding is None:
        from palpation.markers.template import rest_template
        binding = bind_markers(mesh.nodes, mesh.dome_nodes, rest_template())
    through = None
    if not image.is_identity:  # the true camera binds the same template to other nodes
        through = bind_markers_through(mesh.nodes, mesh.dome_nodes, binding.template_px, image)
        binding = replace(through.binding, rest_px=through.anchor_px)
    reqs = [r.resolved(cfg) for r in requests]
    trajs = plan_requests(mesh, cfg, reqs, max_frames)
    schedule, lengths = padded_schedule(trajs)
    first, end = record_windows(trajs, reqs)
    n, n_frames = len(reqs), len(schedule)

    def device_outputs(sim):  # written on the device every frame, read once at the end
        return (MarkerProjector(binding, schedule, mesh.n_nodes, first, end, device=device),
                wp.zeros((n_frames, n), dtype=wp.int32, device=device))

    def per_frame(sim, outputs, frame_index, offset):  # captured with the frame: flags and markers, no host work
        proj, contact_dev = outputs
        wp.launch(record_contact_flags, dim=n, device=device, inputs=[sim.contact_flag, frame_index, offset],
                  outputs=[contact_dev])
        proj.extract_at(sim.x, frame_index, offset)

    failed_at = np.full(n, -1)
    # the simulator's failure flag is sticky, so reading it sparsely (plus at each env's last frame,
    # to tell a failure inside an env's own frames from one after it finished) loses nothing
    checks = set(range(READ_FAILED_EVERY - 1, n_frames, READ_FAILED_EVERY)) | set((lengths - 1).tolist())
    checked_to = 0  # frames [0, checked_to) are covered by earlier checks
    start = time.perf_counter()
    with LockedBatch(mesh, cfg, reqs, trajs, schedule, device, device_outputs, per_frame, progress) as run:
        for f in run:
            if f not in checks:
                continue
            failed_now = run.read(lambda sim, _: sim.failed())
            # blame only envs still inside their own frames since the last check
            bad = failed_now & (failed_at < 0) & (lengths > checked_to)
            failed_at[bad] = f
            checked_to = f + 1
            if np.all((failed_at >= 0) | (lengths <= checked_to)):
                break  # every env has either failed or finished
        markers, centre, contact = run.read(lambda _, out: (*out[0].results(), out[1].numpy().astype(bool)))
    if through is not None:  # the projector ran the nominal camera: map into the true image
        markers = through.markers(markers).astype(np.float32)
        centre = image.apply(centre).astype(np.float32)
    if cfg.markers.anchor != 0.0:  # move the bound rest onto the template (twin.config.MarkerConfig)
        shift = cfg.markers.anchor * (binding.template_px - binding.rest_px)
        markers = (markers + shift).astype(np.float32)
        binding = replace(binding, rest_px=binding.rest_px + shift)
    wall = time.perf_counter() - start

    def labels(i):  # numpy releases the GIL: envs in parallel threads (~10 ms per recorded slide each)
        frames = np.arange(first[i], end[i])
        return marker_labels(markers[: len(frames), i], centre[: len(frames), i], contact[frames, i])

    with ThreadPoolExecutor(max_workers=min(16, os.cpu_count() or 1)) as pool:
        env_labels = dict(zip(np.flatnonzero(failed_at < 0), pool.map(labels, np.flatnonzero(failed_at < 0))))

    records, failed = [], []
    line_A = centreline_A()
    for i, (req, traj) in enumerate(zip(reqs, trajs)):
        params = {**req.twin_params(),
                  "heading_deg": None if np.isnan(traj.heading_deg) else traj.heading_deg}  # strict JSON
        name = req.name or f"env_{i:04d}"
        if failed_at[i] >= 0:
            log.warning("env %d (%s) failed at frame %d with %s", i, name, failed_at[i], params)
            failed.append(FailedRecord(name=name, kind=req.kind, seed=req.seed, params=params,
                                       detected_at_frame=int(failed_at[i])))
            continue
        frames = np.arange(first[i], end[i])
        m, c, k = markers[: len(frames), i], centre[: len(frames), i], contact[frames, i]
        records.append(TrajectoryRecord(
            name=name, kind=req.kind, seed=req.seed, params=params, markers=m, centreline_px=c,
            labels=env_labels[i], contact=k, T_BA=schedule[frames, i], frame_index=frames,
            centreline_A=line_A, rest_markers_px=binding.rest_px.astype(np.float32)))
    return BatchResult(records=records, failed=failed, frames=f + 1, wall_s=wall, failed_mask=failed_at >= 0)


def run_batches(mesh: SensorMesh, cfg: TwinConfig, requests: list[EnvRequest], batch_size: int,
                device: str | None = None, progress: bool = True, max_frames: int | None = None,
                workers: int | None = None) -> list[BatchResult]:
    """`requests` in batches of at most `batch_size`, each cut into `workers` parts that run side by side
    in threads (None: the usable cores on a CPU, where Warp runs a kernel on one core; 1 on CUDA). An env's
    record does not depend on the batch it ran in, so the records (in request order) are the same for any
    cut. Only a batch of one kind and geometry is cut (the same frames for all: the failure checks, at each
    env's end and every READ_FAILED_EVERY frames, and so a failed env's detected_at_frame stay), and only
    when every request has a name (else named by its place in the batch)."""
    if workers is None:
        workers = usable_cores() if resolve_device(device or cfg.device).is_cpu else 1
    if any(not r.name for r in requests):
        workers = 1
    parts = []
    for lo in range(0, len(requests), batch_size):
        chunk = requests[lo: lo + batch_size]
        same = len({(r.kind, r.depth_mm, r.angle_deg) for r in chunk}) == 1
        cut = min(workers, len(chunk)) if same else 1
        parts += [[chunk[i] for i in ix] for ix in np.array_split(np.arange(len(chunk)), cut)]

    def one(part):
        return run_batch(mesh, cfg, part, device=device, progress=progress and len(parts) == 1, max_frames=max_frames)

    return run_parts(one, parts, workers)[0]


def simulate_states(mesh: SensorMesh, cfg: TwinConfig, requests: list[tuple[str, dict]],
                    device: str | None = None, binding: MarkerBinding | None = None,
                    split_by_kind: bool = False, max_frames: int | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """For calibration: markers at the last frame of each (kind, params) request.

    params keys (all optional): any per-env twin parameter (twin.parameters.per_env_keys), vessel,
    heading_offset_deg, depth_mm, angle_deg. Every request is checked before
    anything runs. One batch, or with `split_by_kind` one batch per kind: on a CPU every env costs
    the longest env's frames, so a 36-frame press should not ride along a 398-frame slide.
    Returns (n, 127, 2) float32 pixels (NaN for a failed env) and (n,) bool failed flags.
    """
    allowed = set(per_env_keys()) | set(GEOMETRY_KEYS) | {"vessel"}
    envs = []
    for i, (kind, params) in enumerate(requests):
        unknown = set(params) - allowed
        if unknown:
            raise ValueError(f"request {i} ({kind}): unknown parameters {sorted(unknown)}; "
                             f"use {sorted(allowed)}")
        env = EnvRequest(kind=kind, record="last", name=f"state_{i:04d}", **params)
        waypoints(env.kind, env.heading_offset_deg, env.depth_mm, env.angle_deg)  # bad kind/geometry: fail now
        envs.append(env)
    groups = [list(range(len(envs)))]
    if split_by_kind:
        groups = [[i for i, e in enumerate(envs) if e.kind == k] for k in dict.fromkeys(e.kind for e in envs)]
    out = np.full((len(envs), 127, 2), np.nan, np.float32)
    failed = np.zeros(len(envs), bool)
    for idx in groups:
        result = run_batch(mesh, cfg, [envs[i] for i in idx], binding=binding, device=device,
                           progress=False, max_frames=max_frames)
        failed[idx] = result.failed_mask
        for i, rec in zip(np.asarray(idx)[~result.failed_mask], result.records):
            out[i] = rec.markers[-1]
    return out, failed
