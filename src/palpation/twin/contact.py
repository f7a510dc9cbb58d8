"""Penalty contact of the sensor's surface nodes with the rigid vessel and the phantom surface.

The vessel is an analytic SDF (finite cylinder along world x, SPEC §3.1), evaluated at each sensor
surface node in the world frame; the phantom is the half-space z <= phantom top (off by default,
SPEC §3.3). Normal force on a node at signed distance d < 0 with outward normal n:
    F_n = (k_n + c_n * max(closing speed, 0)) * (-d) * n
which keeps the reference's form where the damping term is also multiplied by the depth (quirk 11).
Tangential: F_t = -t * min(k_t |v_t|, mu |F_n|) for slip |v_t| > slip_eps (reference rule, §3.3).

Compliant phantom (issue 12, `foundation_on`, off by default): the phantom is a Winkler foundation, pressure
= k_f * penetration, so a surface node of projected rest area A_i at depth d < 0 gets the stiffness
k_f * s * A_i in the same penalty form. Vessels are stiffer inclusions (cylinders of diameter D with their
axis at depth h below the top, along the scene's centreline segments, E_vessel = ratio * E_phantom):
in a column of height H (scene.phantom_thickness) the foundation is springs in series,
1/k = (H - t)/E + t/(ratio E), so s = 1 / (1 - (t/H)(1 - 1/ratio)), where t is the inclusion's thickness
under the node. Load spreads at 45 degrees (the 2:1 rule), so the surface sees the vessel over a half-width
w = max(h, D/2) around its axis: t(r) = D sqrt(1 - (r/w)^2) at lateral distance r (0 beyond w).

`eval_centroid_contact` is the reference's own rule (§3.3) as an option: each vessel mesh node
finds the sensor contact triangle with the nearest centroid and pushes its 3 vertices (1/3 each).
"""

from __future__ import annotations

import warp as wp


@wp.struct
class ContactParams:
    k_n: wp.array(dtype=float)  # per env, N/m
    c_n: wp.array(dtype=float)  # per env, N s/m^2
    k_t: wp.array(dtype=float)  # per env, N s/m
    mu: wp.array(dtype=float)  # per env, Coulomb coefficient (vessel and phantom)
    k_s: wp.array(dtype=float)  # per env, phantom surface stiffness, N/m
    c_s: wp.array(dtype=float)  # per env, phantom surface damping, N s/m^2
    vessel: wp.array(dtype=wp.int32)  # per env, 1 = the vessel exists
    vessel_center: wp.vec3
    vessel_half_length: float
    vessel_radius: float
    phantom_top_z: float
    phantom_on: int
    slip_eps: float
    # compliant phantom with vessel inclusions (issue 12); unused unless foundation_on
    k_f: wp.array(dtype=float)  # per env, foundation modulus N/m^3 (pressure per penetration)
    incl_ratio: wp.array(dtype=float)  # per env, E_vessel / E_phantom
    incl_depth: wp.array(dtype=float)  # per env, m, vessel axis below the phantom top
    incl_diameter: wp.array(dtype=float)  # per env, m
    node_area: wp.array(dtype=float)  # per mesh node, projected rest area on the contact triangles, m^2
    seg_a: wp.array(dtype=wp.vec2)  # vessel centreline segments, world x, y (m)
    seg_b: wp.array(dtype=wp.vec2)
    n_seg: int
    phantom_thickness: float
    foundation_on: int


@wp.func
def vessel_sdf(p: wp.vec3, center: wp.vec3, half_length: float, radius: float):
    """Signed distance and outward unit normal of a finite cylinder with its axis along x."""
    q = p - center
    r = wp.sqrt(q[1] * q[1] + q[2] * q[2])
    radial = wp.vec3(0.0, 0.0, 1.0)  # any direction is a normal on the axis itself
    if r > 1.0e-12:
        radial = wp.vec3(0.0, q[1] / r, q[2] / r)
    axial = wp.vec3(wp.sign(q[0]), 0.0, 0.0)
    da = wp.abs(q[0]) - half_length
    dr = r - radius
    if da < 0.0 and dr < 0.0:  # inside: the nearest face
        if da > dr:
            return da, axial
        return dr, radial
    ea = wp.max(da, 0.0)
    er = wp.max(dr, 0.0)
    d = wp.sqrt(ea * ea + er * er)
    return d, wp.normalize(ea * axial + er * radial)


@wp.func
def contact_force(d: float, n: wp.vec3, v: wp.vec3, k_n: float, c_n: float, k_t: float, mu: float,
                  slip_eps: float):
    """Force on a node at depth d < 0 moving with velocity v against a static surface of normal n."""
    closing = wp.max(-wp.dot(v, n), 0.0)
    fn = -(k_n + c_n * closing) * d * n
    vt = v - wp.dot(v, n) * n
    slip = wp.length(vt)
    ft = wp.vec3(0.0)
    if slip > slip_eps:
        ft = -(vt / slip) * wp.min(k_t * slip, mu * wp.length(fn))
    return fn + ft


@wp.func
def segment_distance(q: wp.vec2, a: wp.vec2, b: wp.vec2):
    """Distance from q to the segment ab in the plane."""
    ab = b - a
    ll = wp.dot(ab, ab)
    u = float(0.0)
    if ll > 0.0:
        u = wp.clamp(wp.dot(q - a, ab) / ll, 0.0, 1.0)
    return wp.length(q - (a + u * ab))


@wp.func
def foundation_scale(xi: wp.vec3, env: int, p: ContactParams):
    """Local foundation stiffening s >= 1 by the nearest vessel inclusion (module docstring)."""
    ratio = p.incl_ratio[env]
    if p.n_seg == 0 or ratio == 1.0:
        return 1.0
    q = wp.vec2(xi[0], xi[1])
    r = float(1.0e30)
    for k in range(p.n_seg):
        r = wp.min(r, segment_distance(q, p.seg_a[k], p.seg_b[k]))
    diam = p.incl_diameter[env]
    w = wp.max(p.incl_depth[env], 0.5 * diam)
    if r >= w:
        return 1.0
    t = diam * wp.sqrt(1.0 - (r / w) * (r / w))
    frac = wp.min(t / p.phantom_thickness, 0.95)  # a vessel never fills the whole column
    return 1.0 / (1.0 - frac * (1.0 - 1.0 / ratio))


@wp.func
def surface_contact_force(xi: wp.vec3, vel: wp.vec3, env: int, node: int, p: ContactParams,
                          vessel_sdf_on: int):
    """Vessel (SDF) + phantom force on one surface node, and 1 if it touches the vessel."""
    fc = wp.vec3(0.0)
    touched = int(0)
    if p.vessel[env] != 0 and vessel_sdf_on != 0:
        d, n = vessel_sdf(xi, p.vessel_center, p.vessel_half_length, p.vessel_radius)
        if d < 0.0:
            fc += contact_force(d, n, vel, p.k_n[env], p.c_n[env], p.k_t[env], p.mu[env], p.slip_eps)
            touched = 1
    if p.foundation_on != 0:
        d = xi[2] - p.phantom_top_z
        if d < 0.0:
            k = p.k_f[env] * p.node_area[node] * foundation_scale(xi, env, p)
            fc += contact_force(d, wp.vec3(0.0, 0.0, 1.0), vel, k, p.c_s[env], p.k_t[env], p.mu[env],
                                p.slip_eps)
    elif p.phantom_on != 0:
        d = xi[2] - p.phantom_top_z
        if d < 0.0:
            fc += contact_force(d, wp.vec3(0.0, 0.0, 1.0), vel, p.k_s[env], p.c_s[env], p.k_t[env],
                                p.mu[env], p.slip_eps)
    return fc, touched


@wp.kernel
def eval_contact_forces(
    x: wp.array[wp.vec3],
    v: wp.array[wp.vec3],
    f: wp.array[wp.vec3],
    inv_mass: wp.array[float],
    surface: wp.array[wp.int32],
    n_surface: int,
    n_nodes: int,
    dt: float,
    p: ContactParams,
    vessel_sdf_on: int,
    f_c: wp.array[wp.vec3],
    contact_flag: wp.array[wp.int32],
):
    tid = wp.tid()
    env = tid // n_surface
    node = surface[tid - env * n_surface]
    i = env * n_nodes + node
    # SPEC §2.4: contact sees the velocity already updated by this substep's elastic force
    vel = v[i] + dt * inv_mass[node] * f[i]
    fc, touched = surface_contact_force(x[i], vel, env, node, p, vessel_sdf_on)
    if touched != 0:
        contact_flag[env] = 1
    f_c[i] = fc


@wp.kernel
def record_contact_flags(contact_flag: wp.array[wp.int32], frame_index: wp.array[wp.int32], row_offset: int,
                         history: wp.array2d[wp.int32]):
    """history[frame_index + row_offset, env] = this frame's vessel-contact flag (one graph, every frame)."""
    env = wp.tid()
    history[frame_index[0] + row_offset, env] = contact_flag[env]


@wp.kernel
def eval_centroid_contact(
    x: wp.array[wp.vec3],
    v: wp.array[wp.vec3],
    f: wp.array[wp.vec3],
    inv_mass: wp.array[float],
    tris: wp.array2d[wp.int32],
    n_tris: int,
    n_nodes: int,
    vessel_points: wp.array[wp.vec3],
    n_points: int,
    pose_R: wp.array[wp.mat33],
    pose_t: wp.array[wp.vec3],
    reach: float,
    dt: float,
    p: ContactParams,
    f_c: wp.array[wp.vec3],
    contact_flag: wp.array[wp.int32],
):
    """SPEC §3.3 per (env, vessel node): nearest-centroid triangle, plane depth, barycentric test.

    Adds onto f_c (already holding this substep's per-node phantom force, or zero). Vessel nodes
    farther than `reach` from the tip are skipped: no triangle of the sensor can hold them.
    """
    tid = wp.tid()
    env = tid // n_points
    q = vessel_points[tid - env * n_points]
    if p.vessel[env] == 0 or wp.length(q - pose_t[env]) > reach:
        return
    off = env * n_nodes
    best = float(1.0e30)
    bk = int(0)
    for k in range(n_tris):
        c = (x[tris[k, 0] + off] + x[tris[k, 1] + off] + x[tris[k, 2] + off]) / 3.0
        dist = wp.length_sq(c - q)
        if dist < best:
            best = dist
            bk = k
    ia = tris[bk, 0] + off
    ib = tris[bk, 1] + off
    ic = tris[bk, 2] + off
    p1 = x[ia]
    nrm = wp.cross(x[ib] - p1, x[ic] - p1)
    ln = wp.length(nrm)
    if ln < 1.0e-11:  # degenerate triangle: zero normal, no contact (reference)
        return
    n = nrm / ln
    if wp.dot(n, pose_R[env] @ wp.vec3(0.0, 0.0, 1.0)) < 0.0:  # face out of the dome
        n = -n
    d = wp.dot(q - p1, n)
    e0 = x[ic] - p1
    e1 = x[ib] - p1
    e2 = q - d * n - p1
    d00 = wp.dot(e0, e0)
    d01 = wp.dot(e0, e1)
    d02 = wp.dot(e0, e2)
    d11 = wp.dot(e1, e1)
    d12 = wp.dot(e1, e2)
    inv = 1.0 / (d00 * d11 - d01 * d01)
    u = (d11 * d02 - d01 * d12) * inv
    w = (d00 * d12 - d01 * d02) * inv
    if d < 0.0 and u >= 0.0 and w >= 0.0 and u + w <= 1.0:
        vbar = (v[ia] + dt * inv_mass[ia - off] * f[ia] + v[ib] + dt * inv_mass[ib - off] * f[ib]
                + v[ic] + dt * inv_mass[ic - off] * f[ic]) / 3.0
        # force on the sensor: the vessel's outward direction is -n as seen from the triangle
        fs = contact_force(d, -n, vbar, p.k_n[env], p.c_n[env], p.k_t[env], p.mu[env], p.slip_eps) / 3.0
        wp.atomic_add(f_c, ia, fs)
        wp.atomic_add(f_c, ib, fs)
        wp.atomic_add(f_c, ic, fs)
        contact_flag[env] = 1
