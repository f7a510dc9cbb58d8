"""Symplectic Euler substep, driven base motion, and the divergence check (SPEC §2.4).

Per substep: v += dt F/m (elastic), contact with that velocity, v += dt f_c/m, fixed nodes
v = v_control, x += dt v. The fixed nodes follow each env's rigid pose increment of the frame.
"""

from __future__ import annotations

import warp as wp

from palpation.twin.contact import ContactParams, surface_contact_force


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
def integrate_contact_nodes(
    f: wp.array[wp.vec3],
    v_ctl: wp.array[wp.vec3],
    inv_mass: wp.array[float],
    fixed: wp.array[wp.int32],
    on_surface: wp.array[wp.int32],
    n_nodes: int,
    dt: float,
    p: ContactParams,
    gather: int,
    slot_start: wp.array[wp.int32],
    node_slots: wp.array[wp.int32],
    fs: wp.array[wp.vec3],
    n_slots: int,
    x: wp.array[wp.vec3],
    v: wp.array[wp.vec3],
    f_c: wp.array[wp.vec3],
    contact_flag: wp.array[wp.int32],
):
    """eval_contact_forces (SDF rule) + integrate_nodes in one pass over the nodes; clears f.

    The same arithmetic as the two kernels (an interior node's f_c is zero, so skipping `+ w f_c`
    changes nothing), one launch and one read of x, v, f instead of two. f is left zeroed for the
    next substep's scatter, which saves the memset. With `gather` the elastic force is instead the
    sum of the node's slots of fs, in mesh (tet, corner) order (elasticity.force_slots).
    """
    tid = wp.tid()
    env = tid // n_nodes
    node = tid - env * n_nodes
    w = dt * inv_mass[node]
    fi = wp.vec3(0.0)
    if gather != 0:
        so = env * n_slots
        for j in range(slot_start[node], slot_start[node + 1]):  # empty for a driven node
            fi = fi + fs[so + node_slots[j]]
    else:
        fi = f[tid]
        f[tid] = wp.vec3(0.0)
    vel = v[tid] + w * fi
    xi = x[tid]
    if on_surface[node] != 0:
        fc, touched = surface_contact_force(xi, vel, env, node, p, 1)
        f_c[tid] = fc
        if touched != 0:
            contact_flag[env] = 1
        vel = vel + w * fc
    if fixed[node] != 0:
        vel = v_ctl[tid]
    v[tid] = vel
    x[tid] = xi + dt * vel


@wp.kernel
def load_frame_poses(
    sched_R: wp.array2d[wp.mat33],
    sched_t: wp.array2d[wp.vec3],
    sched_dR: wp.array2d[wp.mat33],
    sched_dt: wp.array2d[wp.vec3],
    frame_index: wp.array[wp.int32],
    row_offset: int,
    pose_R: wp.array[wp.mat33],
    pose_t: wp.array[wp.vec3],
    delta_R_minus_I: wp.array[wp.mat33],
    delta_t: wp.array[wp.vec3],
):
    """Frame start of a device-side schedule: row frame_index + row_offset into the per-env pose
    arrays that step_frame otherwise fills from the host (a graph replays every frame unchanged)."""
    env = wp.tid()
    row = frame_index[0] + row_offset
    pose_R[env] = sched_R[row, env]
    pose_t[env] = sched_t[row, env]
    delta_R_minus_I[env] = sched_dR[row, env]
    delta_t[env] = sched_dt[row, env]


@wp.kernel
def advance_frame(frame_index: wp.array[wp.int32]):
    """Frame end: frames since reset += 1, on the device (read by the kernels of the next frame)."""
    frame_index[0] = frame_index[0] + 1


@wp.kernel
def snap_fixed_nodes(x_u: wp.array[wp.vec3], fixed: wp.array[wp.int32], n_nodes: int,
                     x: wp.array[wp.vec3]):
    """Frame end: put driven nodes exactly on the pose; 124 float32 steps of x += dt v drift ~2e-7 m."""
    tid = wp.tid()
    if fixed[tid % n_nodes] != 0:
        x[tid] = x_u[tid]


@wp.kernel
def check_nodes(x: wp.array[wp.vec3], n_nodes: int, max_abs: float, frame_index: wp.array[wp.int32],
                every: int, failed: wp.array[wp.int32]):
    """NaN, inf or |x| beyond max_abs marks the node's env as failed (sticky until reset).

    Runs only when frame_index % every == 0, so a graph replaying every frame checks every few."""
    if frame_index[0] % every != 0:
        return
    tid = wp.tid()
    p = x[tid]
    if not (wp.isfinite(p) and wp.length(p) <= max_abs):
        failed[tid // n_nodes] = 1


@wp.kernel
def check_tets(x: wp.array[wp.vec3], tets: wp.array2d[wp.int32], dm_inv: wp.array[wp.mat33],
               n_tets: int, n_nodes: int, frame_index: wp.array[wp.int32], every: int,
               failed: wp.array[wp.int32]):
    """An inverted or flat tet (J <= 0, or not finite) marks its env as failed (gated as check_nodes)."""
    if frame_index[0] % every != 0:
        return
    tid = wp.tid()
    env = tid // n_tets
    t = tid - env * n_tets
    off = env * n_nodes
    x3 = x[tets[t, 3] + off]
    ds = wp.matrix_from_cols(x[tets[t, 0] + off] - x3, x[tets[t, 1] + off] - x3, x[tets[t, 2] + off] - x3)
    J = wp.determinant(ds @ dm_inv[t])
    if not (J > 0.0):
        failed[env] = 1
