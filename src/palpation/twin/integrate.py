"""Symplectic Euler substep, driven base motion, and the divergence check (SPEC §2.4).

Per substep: v += dt F/m (elastic), contact with that velocity, v += dt f_c/m, fixed nodes
v = v_control, x += dt v. The fixed nodes follow each env's rigid pose increment of the frame.
"""

from __future__ import annotations

import warp as wp


@wp.kernel
def set_control_velocity(
    rest_body: wp.array[wp.vec3],
    pose_R: wp.array[wp.mat33],
    pose_t: wp.array[wp.vec3],
    delta_R_minus_I: wp.array[wp.mat33],
    delta_t: wp.array[wp.vec3],
    n_nodes: int,
    frame_dt: float,
    x_u: wp.array[wp.vec3],
    v_ctl: wp.array[wp.vec3],
):
    """Undeformed copy at the frame start, pose increment T_next T_cur^-1 -> constant v_control.

    The increment arrives as (dR - I, dt), computed in float64 on the host, so the small per-frame
    displacement is not the difference of two large float32 positions. x_u is left at the frame
    end (the next pose), which is what the readers report after step_frame.
    """
    tid = wp.tid()
    env = tid // n_nodes
    xc = pose_R[env] @ rest_body[tid - env * n_nodes] + pose_t[env]
    disp = delta_R_minus_I[env] @ xc + delta_t[env]
    v_ctl[tid] = disp / frame_dt
    x_u[tid] = xc + disp


@wp.kernel
def reset_velocities(
    v_ctl: wp.array[wp.vec3],
    fixed: wp.array[wp.int32],
    n_nodes: int,
    zero_free: int,
    v: wp.array[wp.vec3],
):
    """Frame start: fixed nodes take v_control; free nodes lose their velocity if zero_free."""
    tid = wp.tid()
    if fixed[tid % n_nodes] != 0:
        v[tid] = v_ctl[tid]
    elif zero_free != 0:
        v[tid] = wp.vec3(0.0)


@wp.kernel
def integrate_nodes(
    f: wp.array[wp.vec3],
    f_c: wp.array[wp.vec3],
    v_ctl: wp.array[wp.vec3],
    inv_mass: wp.array[float],
    fixed: wp.array[wp.int32],
    n_nodes: int,
    dt: float,
    x: wp.array[wp.vec3],
    v: wp.array[wp.vec3],
):
    tid = wp.tid()
    node = tid % n_nodes
    w = dt * inv_mass[node]
    vel = v[tid] + w * f[tid]  # the same two-step sum the contact kernel saw
    vel = vel + w * f_c[tid]
    if fixed[node] != 0:
        vel = v_ctl[tid]
    v[tid] = vel
    x[tid] = x[tid] + dt * vel


@wp.kernel
def snap_fixed_nodes(x_u: wp.array[wp.vec3], fixed: wp.array[wp.int32], n_nodes: int,
                     x: wp.array[wp.vec3]):
    """Frame end: put driven nodes exactly on the pose; 124 float32 steps of x += dt v drift ~2e-7 m."""
    tid = wp.tid()
    if fixed[tid % n_nodes] != 0:
        x[tid] = x_u[tid]


@wp.kernel
def check_nodes(x: wp.array[wp.vec3], n_nodes: int, max_abs: float, failed: wp.array[wp.int32]):
    """NaN, inf or |x| beyond max_abs marks the node's env as failed (sticky until reset)."""
    tid = wp.tid()
    p = x[tid]
    if not (wp.isfinite(p) and wp.length(p) <= max_abs):
        failed[tid // n_nodes] = 1


@wp.kernel
def check_tets(x: wp.array[wp.vec3], tets: wp.array2d[wp.int32], dm_inv: wp.array[wp.mat33],
               n_tets: int, n_nodes: int, failed: wp.array[wp.int32]):
    """An inverted or flat tet (J <= 0, or not finite) marks its env as failed."""
    tid = wp.tid()
    env = tid // n_tets
    t = tid - env * n_tets
    off = env * n_nodes
    x3 = x[tets[t, 3] + off]
    ds = wp.matrix_from_cols(x[tets[t, 0] + off] - x3, x[tets[t, 1] + off] - x3, x[tets[t, 2] + off] - x3)
    J = wp.determinant(ds @ dm_inv[t])
    if not (J > 0.0):
        failed[env] = 1
