"""N independent sensor twins advanced by the same kernel launches (the Warp `Example` shape).

`__init__` allocates every array; `simulate()` runs one frame (begin-of-frame kernels and the
substeps) without allocating, so it is captured once as a graph (CUDA, and the CPU since Warp 1.19)
and `step_frame` replays it with one small host-to-device copy of the poses per frame. With a whole
schedule uploaded (`set_schedule`), `step_scheduled` replays one graph per frame and the host sends
nothing: the frame index lives on the device.
"""

from __future__ import annotations

import logging
from contextlib import nullcontext

import numpy as np
import warp as wp

from palpation.twin.config import TwinConfig
from palpation.twin.contact import ContactParams, eval_centroid_contact, eval_contact_forces
from palpation.twin.elasticity import (courant_dt, eval_elastic_forces, eval_elastic_forces_layered,
                                       force_slots, lame_parameters, lumped_mass, rest_shape)
from palpation.twin.integrate import (advance_frame, check_nodes, check_tets, integrate_contact_nodes,
                                      integrate_nodes, load_frame_poses, reset_velocities,
                                      set_control_velocity, snap_fixed_nodes)
from palpation.twin.mesh import (SensorMesh, build_vessel_points, morton_order, per_mesh, projected_node_area,
                                 shell_weights)
from palpation.twin.resident import frame_kernel, frame_kernels, launch_resident, resident_layout
from palpation.twin.warp_runtime import CAPTURE_LOCK, resolve_device, warp_exclusive
from palpation.twin.parameters import (CONTACT_KEYS, ENV_KEYS, LAYERED_KEYS, by_env_key, env_values, layered_values,
                                       per_env_keys)

log = logging.getLogger(__name__)


class BatchedTwin:
    @warp_exclusive
    def __init__(self, mesh: SensorMesh, n_envs: int, cfg: TwinConfig | None = None,
                 env_params: dict[str, np.ndarray] | None = None, device: str | None = None):
        self.cfg = cfg = (cfg or TwinConfig()).validate()
        self.device = resolve_device(device or cfg.device)
        self.mesh, self.n_envs = mesh, int(n_envs)
        self.n_nodes, self.n_tets = mesh.n_nodes, mesh.n_tets
        self.n_surface = len(mesh.surface_nodes)
        self.dt, self.substeps = float(cfg.integrator.dt), int(cfg.integrator.substeps)
        self.frame_dt = self.dt * self.substeps
        n, N, dev = self.n_envs, self.n_nodes, self.device

        # Tets with a free or contact node first, in mesh order; the force kernels run over those
        # only. A tet of driven interior nodes alone (15 % of the reference mesh) only pushes nodes
        # whose velocity the control overwrites, so skipping it changes nothing, not even the order
        # of the sums at any other node. The health check sees all tets.
        on_surface = np.isin(np.arange(N), mesh.surface_nodes)
        needs_force = ~mesh.fixed | on_surface
        moving = needs_force[mesh.tets].any(axis=1)
        moving_ix = np.flatnonzero(moving)
        mode = cfg.integrator.force_sum
        self.gather = mode == "gather" or (mode == "auto" and dev.is_cuda and cfg.contact.rule == "sdf")
        run_index = np.arange(len(moving_ix))  # where each moving tet (mesh order) runs
        if dev.is_cuda or self.gather:  # run them along a space-filling curve: a warp's tets share
            # nodes, so the x, v gathers hit L1 (3x fewer sectors than mesh order on the reference
            # mesh). Gather sums keep the mesh order, so the results do not change (a CPU scatter,
            # whose sums follow the tet order, keeps the mesh order).
            perm = morton_order(mesh.nodes[mesh.tets[moving_ix]].mean(axis=1))
            run_index[perm] = np.arange(len(perm))
        slots, start = force_slots(mesh.tets[moving_ix], needs_force, N, run_index)  # sums in mesh order
        moving_ix = moving_ix[np.argsort(run_index)]
        # the frame-resident kernel's layout (cfg.integrator.kernel, issue 17); shell fractions per mesh tet
        th = cfg.material.shell_thickness
        shell = per_mesh(mesh, ("shell", th), lambda: shell_weights(mesh.nodes, mesh.tets, th))
        self.resident = resident_layout(mesh, needs_force, dev, cfg, n, shell)  # None: the streamed kernels
        self._resident_now = self.resident is not None  # the kernel of the frame being run (resident.frame_kernel)
        self.tet_order = np.concatenate([moving_ix, np.flatnonzero(~moving)])
        self.n_force_tets = len(moving_ix)
        tets = mesh.tets[self.tet_order]
        dm_inv, _ = rest_shape(mesh.nodes, tets)
        mass = lumped_mass(mesh.nodes, mesh.tets, cfg.material.rho, cfg.integrator.mass_scale)
        self.rest_body = wp.array(mesh.nodes, dtype=wp.vec3, device=dev)
        self.tets = wp.array(tets, dtype=wp.int32, device=dev)
        self.dm_inv = wp.array(dm_inv, dtype=wp.mat33, device=dev)
        self.inv_mass = wp.array(1.0 / mass, dtype=float, device=dev)
        self.fixed = wp.array(mesh.fixed.astype(np.int32), dtype=wp.int32, device=dev)
        self.surface = wp.array(mesh.surface_nodes, dtype=wp.int32, device=dev)
        self.on_surface = wp.array(on_surface, dtype=wp.int32, device=dev)
        self.n_slots = 4 * self.n_force_tets if self.gather else 0  # per env: 4 corners per tet
        self.node_slots = wp.array(slots if self.gather else np.zeros(1), dtype=wp.int32, device=dev)
        self.slot_start = wp.array(start, dtype=wp.int32, device=dev)
        self.fs = wp.zeros(max(n * self.n_slots, 1), dtype=wp.vec3, device=dev)  # corner forces, gather

        # state, flat over envs: env e owns [e*N, (e+1)*N)
        self.x, self.v, self.f, self.f_c, self.v_ctl, self.x_u = (
            wp.zeros(n * N, dtype=wp.vec3, device=dev) for _ in range(6))
        self.env_mu, self.env_lam = (wp.zeros(n, dtype=float, device=dev) for _ in range(2))
        self.contact_flag, self.failed_flag = (wp.zeros(n, dtype=wp.int32, device=dev) for _ in range(2))
        self.pose_R, self.delta_R = (wp.zeros(n, dtype=wp.mat33, device=dev) for _ in range(2))
        self.pose_t, self.delta_t = (wp.zeros(n, dtype=wp.vec3, device=dev) for _ in range(2))
        self.frame_index = wp.zeros(1, dtype=wp.int32, device=dev)  # frames since reset, on the device

        c, s = cfg.contact, cfg.scene
        self.contact = ContactParams()
        for key in CONTACT_KEYS:
            setattr(self.contact, key, wp.zeros(n, dtype=float, device=dev))
        self.contact.vessel = wp.zeros(n, dtype=wp.int32, device=dev)
        self.contact.vessel_center = wp.vec3(s.vessel_center_x, s.vessel_center_y,
                                             s.phantom_top_z - s.vessel_depth)
        self.contact.vessel_half_length = 0.5 * s.vessel_length
        self.contact.vessel_radius = s.vessel_radius
        self.contact.phantom_top_z = s.phantom_top_z
        self.contact.phantom_on = int(c.phantom_contact)
        self.contact.slip_eps = c.slip_eps
        self.contact.foundation_on = int(c.phantom_contact and c.phantom_model == "foundation")
        self.contact.phantom_thickness = s.phantom_thickness
        self.contact.node_area = wp.array(projected_node_area(mesh), dtype=float, device=dev)
        self.set_inclusions(np.asarray(s.inclusions, np.float64).reshape(-1, 2, 2))

        self.centroid_rule = c.rule == "centroid"
        if self.centroid_rule:
            center = (s.vessel_center_x, s.vessel_center_y, s.phantom_top_z - s.vessel_depth)
            pts = build_vessel_points(center, s.vessel_radius, s.vessel_length)
            self.vessel_points = wp.array(pts, dtype=wp.vec3, device=dev)
            self.contact_tris = wp.array(mesh.contact_tris, dtype=wp.int32, device=dev)
            # no sensor triangle lies farther from the tip than the rest radius plus 5 mm of travel
            self.reach = float(np.linalg.norm(mesh.nodes, axis=1).max()) + 0.005
        if cfg.layered:  # shell fraction per tet, stored once like Dm^-1
            self.tet_shell = wp.array(shell[self.tet_order].astype(np.float32), dtype=float, device=dev)
            for key in LAYERED_KEYS:  # env_alpha, env_shell_ratio: read by the layered kernel
                setattr(self, f"env_{key}", wp.zeros(n, dtype=float, device=dev))
        self.set_env_params(env_params or {})
        self._pose = np.tile(np.eye(4), (n, 1, 1))
        self.frame = 0
        self.use_graph = True  # CUDA graphs; CPU graphs replay natively (Warp >= 1.19), 0.2 us a launch
        self._graphs, self._sched_graphs = {}, {}  # captured frames, by kernel (True: resident)
        self._schedule = None
        limit = courant_dt(mesh.nodes, mesh.tets, cfg.material.E, cfg.material.nu, cfg.material.rho,
                           cfg.integrator.mass_scale, cfg.material.lame)
        if self.dt > 1.5 * limit:  # measured limits are 1.25-1.5x this estimate (docs/twin.md)
            log.warning("dt=%.3g s is over 1.5x the Courant estimate %.3g s of this mesh: expect "
                        "divergence", self.dt, limit)

    @warp_exclusive
    def set_inclusions(self, segments_m: np.ndarray) -> None:
        """Vessel centreline segments (S, 2, 2) world x, y metres of the compliant phantom (twin.contact)."""
        seg = np.asarray(segments_m, np.float64).reshape(-1, 2, 2)
        if not np.all(np.isfinite(seg)):
            raise ValueError("set_inclusions: vessel segments must be finite world x, y metres")
        pad = seg if len(seg) else np.zeros((1, 2, 2))  # Warp arrays need one element
        self.contact.seg_a = wp.array(pad[:, 0].astype(np.float32), dtype=wp.vec2, device=self.device)
        self.contact.seg_b = wp.array(pad[:, 1].astype(np.float32), dtype=wp.vec2, device=self.device)
        self.contact.n_seg = len(seg)
        self._graphs, self._sched_graphs = {}, {}  # a captured graph holds the old struct

    # ---- parameters and state -------------------------------------------------------------
    @warp_exclusive
    def set_env_params(self, params: dict[str, np.ndarray]) -> None:
        """Per-env values of the registry's parameters (twin.parameters; scalars broadcast) and the
        vessel switch; a key left out takes the config's value. Scope "layered" keys (alpha,
        shell_ratio) may differ from the config only with the layered kernel (cfg.layered)."""
        keys = (*per_env_keys(), "vessel")
        unknown = set(params) - set(keys)
        if unknown:
            raise ValueError(f"unknown env parameter(s) {sorted(unknown)}: use {keys}")
        cfg, m = self.cfg, self.cfg.material
        vals = {}
        for key in ENV_KEYS:
            vals[key] = env_values(key, params.get(key, by_env_key(key).default(cfg)), self.n_envs)
        vals["vessel"] = env_values("vessel", params.get("vessel", float(cfg.contact.vessel)), self.n_envs)
        if np.any(vals["E"] <= 0) or np.any((vals["nu"] <= 0) | (vals["nu"] >= 0.5)):
            raise ValueError(f"env parameters: need E > 0 and 0 < nu < 0.5, got E={vals['E']}, "
                             f"nu={vals['nu']}")
        extras = layered_values(params, cfg, self.n_envs)
        mu, lam = lame_parameters(vals["E"], vals["nu"], m.lame)
        self.env_mu.assign(mu.astype(np.float32))
        self.env_lam.assign(lam.astype(np.float32))
        for key in CONTACT_KEYS:
            getattr(self.contact, key).assign(vals[key].astype(np.float32))
        self.contact.vessel.assign((vals["vessel"] != 0).astype(np.int32))
        if cfg.layered:
            for key, values in extras.items():
                getattr(self, f"env_{key}").assign(values.astype(np.float32))
            vals.update(extras)
        self.env_params = vals

    @warp_exclusive
    def reset(self, T_BA: np.ndarray) -> None:
        """Pose every env rigidly (undeformed, at rest); clears contact and failure flags."""
        T = self._check_poses(T_BA)
        X = self.mesh.nodes
        posed = np.einsum("eij,nj->eni", T[:, :3, :3], X) + T[:, None, :3, 3]
        self.x.assign(posed.reshape(-1, 3).astype(np.float32))
        self.x_u.assign(posed.reshape(-1, 3).astype(np.float32))
        for a in (self.v, self.f, self.f_c, self.v_ctl, self.contact_flag, self.failed_flag,
                  self.frame_index):
            a.zero_()
        self._pose, self.frame = T, 0
        self._schedule = None  # a schedule starts from the pose it was set at; its graph may serve the next one

    def step_frame(self, T_BA_next: np.ndarray) -> None:
        """Advance one frame while the fixed nodes move rigidly from the current to the next pose."""
        T_next = self._check_poses(T_BA_next)
        delta = T_next @ np.linalg.inv(self._pose)  # world-frame increment, float64
        with CAPTURE_LOCK:  # the copies, not the replay (warp_runtime.CAPTURE_LOCK)
            self.pose_R.assign(self._pose[:, :3, :3].astype(np.float32))
            self.pose_t.assign(self._pose[:, :3, 3].astype(np.float32))
            self.delta_R.assign((delta[:, :3, :3] - np.eye(3)).astype(np.float32))
            self.delta_t.assign(delta[:, :3, 3].astype(np.float32))
        self._run_frame(self._graphs, scheduled=False)
        self._pose = T_next
        self.frame += 1
        self._schedule, self._sched_graphs = None, {}  # the schedule's increments start elsewhere now

    @warp_exclusive
    def set_schedule(self, T_BA: np.ndarray, extra=None) -> None:
        """Upload a whole pose schedule (F, n, 4, 4) for `step_scheduled`.

        Frame f moves the fixed nodes from pose f - 1 (the current pose for f = 0) to pose f. The
        increments are computed here once, in float64, as `step_frame` computes them per frame, so
        both give bit-identical results. `extra(frame_index, offset)` may launch more kernels after
        the physics of each frame (marker extraction, flag records); they are captured into the
        same graph and must read the schedule row being run as frame_index[0] + offset.
        """
        T = np.asarray(T_BA, dtype=np.float64)
        if T.ndim != 4 or T.shape[1:] != (self.n_envs, 4, 4) or len(T) == 0 or not np.all(np.isfinite(T)):
            raise ValueError(f"schedule must be finite with shape (frames, {self.n_envs}, 4, 4), "
                             f"got {T.shape}")
        prev = np.concatenate([self._pose[None], T[:-1]])
        delta = T @ np.linalg.inv(prev)  # world-frame increments, float64
        rows = [prev[..., :3, :3], prev[..., :3, 3], delta[..., :3, :3] - np.eye(3), delta[..., :3, 3]]
        F = len(T)
        if (self._sched_graphs and extra is self._sched_extra and self.frame == self._sched_start
                and F <= self._sched_arrays[0].shape[0]):  # a reset twin's next schedule (loop.simulate's pool):
            for a, r in zip(self._sched_arrays, rows):  # into the arrays its graph reads, no capture (~0.1 s)
                a.assign(np.concatenate([r, np.zeros((a.shape[0] - F, *r.shape[1:]))]).astype(np.float32))
        else:
            self._sched_arrays = [wp.array(r.astype(np.float32), dtype=kind, device=self.device)
                                  for r, kind in zip(rows, (wp.mat33, wp.vec3, wp.mat33, wp.vec3))]
            self._sched_graphs = {}
        self._schedule, self._sched_start, self._sched_next = T, self.frame, 0
        self._sched_extra = extra

    def step_scheduled(self) -> None:
        """Advance one frame of the uploaded schedule: one graph launch, no host-device traffic."""
        if self._schedule is None or self._sched_next >= len(self._schedule):
            raise ValueError("step_scheduled needs a schedule with frames left: call set_schedule after "
                             "reset (step_frame and reset discard it)")
        self._run_frame(self._sched_graphs, scheduled=True)
        self._pose = self._schedule[self._sched_next]
        self._sched_next += 1
        self.frame += 1

    def _run_frame(self, graphs: dict, scheduled: bool) -> None:
        """One frame, replayed from `graphs` (one per kernel that may run it, resident.frame_kernels). They are
        captured at the first frame under CAPTURE_LOCK (capture is process-wide; it records, runs nothing), before
        the frame takes the tile lock: the locks are always taken in that order."""
        if not self.use_graph:  # every launch a Warp call: all under the lock
            with CAPTURE_LOCK, frame_kernel(self) as resident:
                self._resident_now = resident
                self._frame(scheduled)
            return
        missing = [k for k in frame_kernels(self) if k not in graphs]
        with CAPTURE_LOCK if missing else nullcontext():
            for resident in missing:
                self._resident_now = resident
                with wp.ScopedCapture(device=self.device) as capture:
                    self._frame(scheduled)
                graphs[resident] = capture.graph
        with frame_kernel(self) as resident:
            self._resident_now = resident
            wp.capture_launch(graphs[resident])  # the one Warp call a twin makes outside CAPTURE_LOCK

    def _frame(self, scheduled: bool = False) -> None:
        """One frame as captured: [schedule row ->] poses, physics, [extra,] frame_index += 1, health."""
        n, N, dev = self.n_envs, self.n_nodes, self.device
        offset = -self._sched_start if scheduled else 0
        if scheduled:
            wp.launch(load_frame_poses, dim=n, device=dev,
                      inputs=[*self._sched_arrays, self.frame_index, offset],
                      outputs=[self.pose_R, self.pose_t, self.delta_R, self.delta_t])
        self.simulate()
        if scheduled and self._sched_extra is not None:
            self._sched_extra(self.frame_index, offset)
        wp.launch(advance_frame, dim=1, device=dev, inputs=[self.frame_index])
        self._launch_health(self.cfg.health.check_every)

    @warp_exclusive
    def simulate(self) -> None:
        """One frame: control velocities, velocity reset, substeps, fixed nodes onto the pose.

        No allocation, so it can be captured as a CUDA graph."""
        n, N, dev = self.n_envs, self.n_nodes, self.device
        wp.launch(set_control_velocity, dim=n * N, device=dev,
                  inputs=[self.rest_body, self.pose_R, self.pose_t, self.delta_R, self.delta_t, N,
                          self.frame_dt], outputs=[self.x_u, self.v_ctl])
        wp.launch(reset_velocities, dim=n * N, device=dev,
                  inputs=[self.v_ctl, self.fixed, N, int(self.cfg.integrator.zero_velocity_each_frame)],
                  outputs=[self.v])
        self.contact_flag.zero_()
        if self._resident_now:  # all substeps in one launch, one block per env
            launch_resident(self)
        else:
            for _ in range(self.substeps):
                self.substep()
        wp.launch(snap_fixed_nodes, dim=n * N, device=dev, inputs=[self.x_u, self.fixed, N], outputs=[self.x])

    def substep(self) -> None:  # no lock of its own: simulate, its one caller, holds it
        n, N, dev, d = self.n_envs, self.n_nodes, self.device, self.cfg.damping
        T = self.n_force_tets  # the tets that move come first in self.tets (see __init__)
        if self.centroid_rule:  # else the node pass below leaves f zeroed
            self.f.zero_()
        sink = [self.n_slots, int(self.gather)]  # scatter into f, or stores into fs for the gather
        if self.cfg.layered:
            wp.launch(eval_elastic_forces_layered, dim=n * T, device=dev,
                      inputs=[self.x, self.v, self.tets, self.dm_inv, self.env_mu, self.env_lam,
                              self.tet_shell, self.env_shell_ratio, self.env_alpha, T, N, d.beta, *sink],
                      outputs=[self.f, self.fs])
        else:
            wp.launch(eval_elastic_forces, dim=n * T, device=dev,
                      inputs=[self.x, self.v, self.tets, self.dm_inv, self.env_mu, self.env_lam,
                              T, N, d.alpha, d.beta, *sink], outputs=[self.f, self.fs])
        if not self.centroid_rule:  # SDF contact, integration and clearing f: one pass over the nodes
            wp.launch(integrate_contact_nodes, dim=n * N, device=dev,
                      inputs=[self.f, self.v_ctl, self.inv_mass, self.fixed, self.on_surface, N, self.dt,
                              self.contact, int(self.gather), self.slot_start, self.node_slots, self.fs,
                              self.n_slots],
                      outputs=[self.x, self.v, self.f_c, self.contact_flag])
            return
        if self.n_surface:  # writes every surface node's f_c: per-node vessel SDF and phantom
            wp.launch(eval_contact_forces, dim=n * self.n_surface, device=dev,
                      inputs=[self.x, self.v, self.f, self.inv_mass, self.surface, self.n_surface, N,
                              self.dt, self.contact, int(not self.centroid_rule)],
                      outputs=[self.f_c, self.contact_flag])
        if self.centroid_rule:  # adds onto f_c of contact-triangle (= surface) nodes
            n_pts = self.vessel_points.shape[0]
            wp.launch(eval_centroid_contact, dim=n * n_pts, device=dev,
                      inputs=[self.x, self.v, self.f, self.inv_mass, self.contact_tris,
                              self.contact_tris.shape[0], N, self.vessel_points, n_pts, self.pose_R,
                              self.pose_t, self.reach, self.dt, self.contact],
                      outputs=[self.f_c, self.contact_flag])
        wp.launch(integrate_nodes, dim=n * N, device=dev,
                  inputs=[self.f, self.f_c, self.v_ctl, self.inv_mass, self.fixed, N, self.dt],
                  outputs=[self.x, self.v])

    @warp_exclusive
    def check_health(self) -> None:
        """Flag envs with a non-finite or runaway node, or an inverted tet (SPEC §2.4)."""
        self._launch_health(1)

    def _launch_health(self, every: int) -> None:
        """The health check, run on the device when frame_index % every == 0."""
        n, N, dev = self.n_envs, self.n_nodes, self.device
        wp.launch(check_nodes, dim=n * N, device=dev,
                  inputs=[self.x, N, self.cfg.health.max_abs_position, self.frame_index, every],
                  outputs=[self.failed_flag])
        wp.launch(check_tets, dim=n * self.n_tets, device=dev,
                  inputs=[self.x, self.tets, self.dm_inv, self.n_tets, N, self.frame_index, every],
                  outputs=[self.failed_flag])

    # ---- readers (each one device-to-host copy) -------------------------------------------
    @warp_exclusive
    def positions_world(self) -> np.ndarray:
        """Deformed node positions (n, N, 3) float32, metres, world frame A."""
        return self.x.numpy().reshape(self.n_envs, self.n_nodes, 3)

    @warp_exclusive
    def undeformed_world(self) -> np.ndarray:
        """The kinematic rigid copy at the current pose (n, N, 3) float32."""
        return self.x_u.numpy().reshape(self.n_envs, self.n_nodes, 3)

    @warp_exclusive
    def velocities_world(self) -> np.ndarray:
        return self.v.numpy().reshape(self.n_envs, self.n_nodes, 3)

    @warp_exclusive
    def contact_forces(self) -> np.ndarray:
        """Contact force on every node at the last substep (n, N, 3), newtons."""
        return self.f_c.numpy().reshape(self.n_envs, self.n_nodes, 3)

    @warp_exclusive
    def contact_flags(self) -> np.ndarray:
        """Per env: did any surface node touch the vessel during the last frame."""
        return self.contact_flag.numpy().astype(bool)

    @warp_exclusive
    def failed(self) -> np.ndarray:
        """Per env: diverged or inverted since the last reset (sticky)."""
        return self.failed_flag.numpy().astype(bool)

    @property
    def poses(self) -> np.ndarray:
        """Current T_BA per env (n, 4, 4) float64, as last passed to reset/step_frame."""
        return self._pose.copy()

    def _check_poses(self, T: np.ndarray) -> np.ndarray:
        T = np.asarray(T, dtype=np.float64)
        if T.shape != (self.n_envs, 4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"poses must be finite with shape ({self.n_envs}, 4, 4), got {T.shape}")
        return T
