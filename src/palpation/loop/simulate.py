"""Final-frame markers of many (state, loop parameters) jobs, batched as twin environments.

Every job is one measured state (kind, depth, angle) under one parameter set. Jobs that differ only
in the camera share one simulated environment (the camera acts at projection), so a batch simulates
each distinct physics once. Per env the mount offset composes the planned schedule (the controller
never sees it), and the markers are projected in numpy from the final node positions with a binding
made through that env's camera (markers.bind_markers_through). On a CPU, kinds run as separate
batches: every env costs the longest env's frames.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np

from palpation.loop.effects import split
from palpation.twin.config import TwinConfig
from palpation.twin.markers import CameraBinding, ImageSimilarity, bind_markers_through, project_markers_np
from palpation.twin.mesh import SensorMesh
from palpation.twin.parameters import PARAMETERS
from palpation.twin.runner import EnvRequest, ScheduledBatch, plan_requests
from palpation.twin.trajectory import mount_offset, padded_schedule, with_mount

log = logging.getLogger(__name__)


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
    def __init__(self, mesh: SensorMesh, cfg: TwinConfig, template_px: np.ndarray, device: str | None = None,
                 split_by_kind: bool | None = None, max_frames: int | None = None):
        self.mesh, self.cfg, self.template = mesh, cfg, np.asarray(template_px, np.float64)
        self.device = device or cfg.device
        self.split = str(self.device).startswith("cpu") if split_by_kind is None else bool(split_by_kind)
        self.max_frames = max_frames
        self._bindings: dict[tuple, CameraBinding] = {}
        self.envs_simulated = 0  # distinct physics simulated so far (for the budget log)
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
        groups = [unique] if not self.split else [[u for u in unique if u[0] == k]
                                                  for k in dict.fromkeys(u[0] for u in unique)]
        nodes, poses, failed = {}, {}, {}
        for group in groups:
            n_A, T, bad = self._run(group)
            for i, key in enumerate(group):
                nodes[key], poses[key], failed[key] = n_A[i], T[i], bad[i]
        self.envs_simulated += len(unique)
        out = np.full((len(jobs), len(self.template), 2), np.nan)
        bad_out = np.zeros(len(jobs), bool)
        for j, (key, (_, camera, _, markers)) in enumerate(zip(physics, parts)):
            if failed[key]:
                bad_out[j] = True
                continue
            through = self.binding(camera)
            out[j] = through.markers(project_markers_np(through.binding, nodes[key][None], poses[key][None])[0])
            # anchor: move the (nominal) bound rest onto the template, as twin.config.MarkerConfig
            out[j] += markers.get("anchor", 0.0) * (self.template - through.anchor_px)
        return out, bad_out

    def _run(self, group: list[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Simulate distinct physics to their last frame: final nodes (n, N, 3), poses, failed flags."""
        reqs = [EnvRequest(k, h, depth_mm=d, angle_deg=a, record="last", **dict(params)).resolved(self.cfg)
                for k, d, a, h, params, _ in group]
        trajs = plan_requests(self.mesh, self.cfg, reqs, self.max_frames)
        trajs = [with_mount(t, mount_offset(**{"dz_m" if k == "dz" else k: v for k, v in mount}))
                 if mount else t for t, (*_, mount) in zip(trajs, group)]
        schedule, lengths = padded_schedule(trajs)
        batch = ScheduledBatch(self.mesh, self.cfg, reqs, trajs, schedule, self.device)
        nodes = np.full((len(group), self.mesh.n_nodes, 3), np.nan, np.float32)
        failed = np.zeros(len(group), bool)
        ends = {int(e) - 1 for e in lengths}
        for f in batch.frames():
            if f in ends:  # read only where some env ends; the failure flag is sticky
                done = lengths - 1 == f
                nodes[done] = batch.sim.positions_world()[done]
                failed[done] = batch.sim.failed()[done]
        T_last = np.stack([t.T_BA[-1] for t in trajs])
        return nodes, T_last, failed | ~np.all(np.isfinite(nodes), axis=(1, 2))
