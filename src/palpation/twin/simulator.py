"""N independent sensor twins advanced by the same kernel launches (the Warp `Example` shape).

`__init__` allocates every array; `simulate()` runs one frame (begin-of-frame kernels and the
substeps) without allocating, so on CUDA it is captured once as a graph and `step_frame` replays
it. One small host-to-device copy of the poses per frame; no host sync inside a frame.
"""

from __future__ import annotations

import logging

import numpy as np
import warp as wp

from palpation.twin.config import TwinConfig
from palpation.twin.contact import ContactParams, eval_centroid_contact, eval_contact_forces
from palpation.twin.elasticity import (courant_dt, eval_elastic_forces, lame_parameters, lumped_mass,
                                       rest_shape)
from palpation.twin.integrate import (check_nodes, check_tets, integrate_nodes, reset_velocities,
                                      set_control_velocity, snap_fixed_nodes)
from palpation.twin.mesh import SensorMesh, build_vessel_points

log = logging.getLogger(__name__)

# per-env parameters a caller may set; the rest of the physics is shared by all envs
ENV_PARAM_KEYS = ("E", "nu", "k_n", "c_n", "k_t", "mu", "k_s", "c_s", "vessel")


def resolve_device(name: str):
    """`cuda` when present, else the CPU (the configs say cuda for the paper profile)."""
    if str(name).startswith("cuda") and not wp.is_cuda_available():
        log.warning("device %r requested but CUDA is not available: running on the CPU", name)
        name = "cpu"
    return wp.get_device(name)


class BatchedTwin:
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

        dm_inv, _ = rest_shape(mesh.nodes, mesh.tets)
        mass = lumped_mass(mesh.nodes, mesh.tets, cfg.material.rho, cfg.integrator.mass_scale)
        self.rest_body = wp.array(mesh.nodes, dtype=wp.vec3, device=dev)
        self.tets = wp.array(mesh.tets, dtype=wp.int32, device=dev)
        self.dm_inv = wp.array(dm_inv, dtype=wp.mat33, device=dev)
        self.inv_mass = wp.array(1.0 / mass, dtype=float, device=dev)
        self.fixed = wp.array(mesh.fixed.astype(np.int32), dtype=wp.int32, device=dev)
        self.surface = wp.array(mesh.surface_nodes, dtype=wp.int32, device=dev)

        # state, flat over envs: env e owns [e*N, (e+1)*N)
        self.x, self.v, self.f, self.f_c, self.v_ctl, self.x_u = (
            wp.zeros(n * N, dtype=wp.vec3, device=dev) for _ in range(6))
        self.env_mu, self.env_lam = (wp.zeros(n, dtype=float, device=dev) for _ in range(2))
        self.contact_flag, self.failed_flag = (wp.zeros(n, dtype=wp.int32, device=dev) for _ in range(2))
        self.pose_R, self.delta_R = (wp.zeros(n, dtype=wp.mat33, device=dev) for _ in range(2))
        self.pose_t, self.delta_t = (wp.zeros(n, dtype=wp.vec3, device=dev) for _ in range(2))

        c, s = cfg.contact, cfg.scene
        self.contact = ContactParams()
        for key in ("k_n", "c_n", "k_t", "mu", "k_s", "c_s"):
            setattr(self.contact, key, wp.zeros(n, dtype=float, device=dev))
        self.contact.vessel = wp.zeros(n, dtype=wp.int32, device=dev)
        self.contact.vessel_center = wp.vec3(s.vessel_center_x, s.vessel_center_y,
                                             s.phantom_top_z - s.vessel_depth)
        self.contact.vessel_half_length = 0.5 * s.vessel_length
        self.contact.vessel_radius = s.vessel_radius
        self.contact.phantom_top_z = s.phantom_top_z
        self.contact.phantom_on = int(c.phantom_contact)
        self.contact.slip_eps = c.slip_eps

        self.centroid_rule = c.rule == "centroid"
        if self.centroid_rule:
            center = (s.vessel_center_x, s.vessel_center_y, s.phantom_top_z - s.vessel_depth)
            pts = build_vessel_points(center, s.vessel_radius, s.vessel_length)
            self.vessel_points = wp.array(pts, dtype=wp.vec3, device=dev)
            self.contact_tris = wp.array(mesh.contact_tris, dtype=wp.int32, device=dev)
            # no sensor triangle lies farther from the tip than the rest radius plus 5 mm of travel
            self.reach = float(np.linalg.norm(mesh.nodes, axis=1).max()) + 0.005
        self.set_env_params(env_params or {})
        self._pose = np.tile(np.eye(4), (n, 1, 1))
        self.frame = 0
        self.use_graph = self.device.is_cuda
        self.graph = None
        limit = courant_dt(mesh.nodes, mesh.tets, cfg.material.E, cfg.material.nu, cfg.material.rho,
                           cfg.integrator.mass_scale, cfg.material.lame)
        if self.dt > 1.5 * limit:  # measured limits are 1.25-1.5x this estimate (docs/twin.md)
            log.warning("dt=%.3g s is over 1.5x the Courant estimate %.3g s of this mesh: expect "
                        "divergence", self.dt, limit)

    # ---- parameters and state -------------------------------------------------------------
    def set_env_params(self, params: dict[str, np.ndarray]) -> None:
        """Per-env E, nu, k_n, c_n, k_t, mu, k_s, c_s, vessel (scalars broadcast); others from cfg."""
        unknown = set(params) - set(ENV_PARAM_KEYS)
        if unknown:
            raise ValueError(f"unknown env parameter(s) {sorted(unknown)}: use {ENV_PARAM_KEYS}")
        c, m = self.cfg.contact, self.cfg.material
        defaults = {"E": m.E, "nu": m.nu, "k_n": c.k_n, "c_n": c.c_n, "k_t": c.k_t, "mu": c.mu,
                    "k_s": c.k_s, "c_s": c.c_s, "vessel": float(c.vessel)}
        vals = {}
        for key, default in defaults.items():
            a = np.asarray(params.get(key, default), np.float64)
            if a.ndim > 1 or a.size not in (1, self.n_envs):
                raise ValueError(f"env parameter {key}: need a scalar or {self.n_envs} values, "
                                 f"got shape {a.shape}")
            a = np.broadcast_to(a.reshape(-1), (self.n_envs,))
            if not np.all(np.isfinite(a)):
                raise ValueError(f"env parameter {key}: values must be finite, got {a}")
            vals[key] = a
        if np.any(vals["E"] <= 0) or np.any((vals["nu"] <= 0) | (vals["nu"] >= 0.5)):
            raise ValueError(f"env parameters: need E > 0 and 0 < nu < 0.5, got E={vals['E']}, "
                             f"nu={vals['nu']}")
        mu, lam = lame_parameters(vals["E"], vals["nu"], m.lame)
        self.env_mu.assign(mu.astype(np.float32))
        self.env_lam.assign(lam.astype(np.float32))
        for key in ("k_n", "c_n", "k_t", "mu", "k_s", "c_s"):
            getattr(self.contact, key).assign(vals[key].astype(np.float32))
        self.contact.vessel.assign((vals["vessel"] != 0).astype(np.int32))
        self.env_params = vals

    def reset(self, T_BA: np.ndarray) -> None:
        """Pose every env rigidly (undeformed, at rest); clears contact and failure flags."""
        T = self._check_poses(T_BA)
        X = self.mesh.nodes
        posed = np.einsum("eij,nj->eni", T[:, :3, :3], X) + T[:, None, :3, 3]
        self.x.assign(posed.reshape(-1, 3).astype(np.float32))
        self.x_u.assign(posed.reshape(-1, 3).astype(np.float32))
        for a in (self.v, self.f, self.f_c, self.v_ctl, self.contact_flag, self.failed_flag):
            a.zero_()
        self._pose, self.frame = T, 0

    def step_frame(self, T_BA_next: np.ndarray) -> None:
        """Advance one frame while the fixed nodes move rigidly from the current to the next pose."""
        T_next = self._check_poses(T_BA_next)
        delta = T_next @ np.linalg.inv(self._pose)  # world-frame increment, float64
        self.pose_R.assign(self._pose[:, :3, :3].astype(np.float32))
        self.pose_t.assign(self._pose[:, :3, 3].astype(np.float32))
        self.delta_R.assign((delta[:, :3, :3] - np.eye(3)).astype(np.float32))
        self.delta_t.assign(delta[:, :3, 3].astype(np.float32))
        if self.use_graph:
            if self.graph is None:
                with wp.ScopedCapture(device=self.device) as capture:
                    self.simulate()
                self.graph = capture.graph
            wp.capture_launch(self.graph)
        else:
            self.simulate()
        self._pose = T_next
        self.frame += 1
        if self.frame % self.cfg.health.check_every == 0:
            self.check_health()

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
        for _ in range(self.substeps):
            self.substep()
        wp.launch(snap_fixed_nodes, dim=n * N, device=dev, inputs=[self.x_u, self.fixed, N], outputs=[self.x])

    def substep(self) -> None:
        n, N, dev, d = self.n_envs, self.n_nodes, self.device, self.cfg.damping
        self.f.zero_()
        wp.launch(eval_elastic_forces, dim=n * self.n_tets, device=dev,
                  inputs=[self.x, self.v, self.tets, self.dm_inv, self.env_mu, self.env_lam,
                          self.n_tets, N, d.alpha, d.beta], outputs=[self.f])
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

    def check_health(self) -> None:
        """Flag envs with a non-finite or runaway node, or an inverted tet (SPEC §2.4)."""
        n, N, dev = self.n_envs, self.n_nodes, self.device
        wp.launch(check_nodes, dim=n * N, device=dev,
                  inputs=[self.x, N, self.cfg.health.max_abs_position], outputs=[self.failed_flag])
        wp.launch(check_tets, dim=n * self.n_tets, device=dev,
                  inputs=[self.x, self.tets, self.dm_inv, self.n_tets, N], outputs=[self.failed_flag])

    # ---- readers (each one device-to-host copy) -------------------------------------------
    def positions_world(self) -> np.ndarray:
        """Deformed node positions (n, N, 3) float32, metres, world frame A."""
        return self.x.numpy().reshape(self.n_envs, self.n_nodes, 3)

    def undeformed_world(self) -> np.ndarray:
        """The kinematic rigid copy at the current pose (n, N, 3) float32."""
        return self.x_u.numpy().reshape(self.n_envs, self.n_nodes, 3)

    def velocities_world(self) -> np.ndarray:
        return self.v.numpy().reshape(self.n_envs, self.n_nodes, 3)

    def contact_forces(self) -> np.ndarray:
        """Contact force on every node at the last substep (n, N, 3), newtons."""
        return self.f_c.numpy().reshape(self.n_envs, self.n_nodes, 3)

    def contact_flags(self) -> np.ndarray:
        """Per env: did any surface node touch the vessel during the last frame."""
        return self.contact_flag.numpy().astype(bool)

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
