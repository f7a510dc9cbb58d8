"""Stable Neo-Hookean elasticity on linear tets with the reference's damping (SPEC §2.3), batched.

Environment e owns nodes [e*N, (e+1)*N) of the flat node arrays and the tets of the shared
(T, 4) connectivity shifted by e*N, so connectivity, Dm^-1 and rest volumes are stored once.
Dm^-1 comes from the body-frame rest shape: for an isotropic energy the nodal forces equal those
of the reference's world-posed Dm^-1 exactly (P(F R^T) = P(F) R^T), so posing needs no recompute.
"""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.func
def neo_hookean_stress(F: wp.mat33, mu: float, lam: float):
    """First Piola stress of the stable Neo-Hookean energy (Smith et al. 2018), as SPEC §2.3."""
    f0 = wp.vec3(F[0, 0], F[1, 0], F[2, 0])
    f1 = wp.vec3(F[0, 1], F[1, 1], F[2, 1])
    f2 = wp.vec3(F[0, 2], F[1, 2], F[2, 2])
    dJdF = wp.matrix_from_cols(wp.cross(f1, f2), wp.cross(f2, f0), wp.cross(f0, f1))
    ic = wp.dot(f0, f0) + wp.dot(f1, f1) + wp.dot(f2, f2)
    alpha = 1.0 + 0.75 * mu / lam
    return mu * (1.0 - 1.0 / (ic + 1.0)) * F + lam * (wp.determinant(F) - alpha) * dJdF


@wp.func
def deposit_forces(f: wp.array[wp.vec3], fs: wp.array[wp.vec3], t: int, slot_off: int, i0: int, i1: int,
                   i2: int, i3: int, g0: wp.vec3, g1: wp.vec3, g2: wp.vec3, gather: int):
    """A tet's corner forces (the 4th is -(g0 + g1 + g2)): atomic adds into f ("scatter"), or 4
    contiguous plain stores at fs[slot_off + 4 t] that the node pass sums in a fixed order ("gather":
    no float atomics, so GPU runs are deterministic; on the CPU both give the same sums bit for bit)."""
    if gather != 0:
        b = slot_off + 4 * t  # a warp writes 32 x 48 contiguous bytes: no partial sectors
        fs[b] = g0
        fs[b + 1] = g1
        fs[b + 2] = g2
        fs[b + 3] = -(g0 + g1 + g2)
    else:
        wp.atomic_add(f, i0, g0)
        wp.atomic_add(f, i1, g1)
        wp.atomic_add(f, i2, g2)
        wp.atomic_add(f, i3, -(g0 + g1 + g2))


@wp.func
def tet_forces(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3, v0: wp.vec3, v1: wp.vec3,
               v2: wp.vec3, v3: wp.vec3, B: wp.mat33, mu: float, lam: float, alpha: float, beta: float):
    """Elastic + damping force on nodes 0-2 of one tet (node 3 takes minus their sum)."""
    ds = wp.matrix_from_cols(x0 - x3, x1 - x3, x2 - x3)
    P = neo_hookean_stress(ds @ B, mu, lam)
    vol = wp.abs(wp.determinant(ds)) / 6.0  # current volume: reference quirk 11
    H = -vol * (P @ wp.transpose(B))
    # damping acts on velocities relative to node 3 and is not mass weighted (SPEC §2.3)
    g0 = (1.0 - beta) * wp.vec3(H[0, 0], H[1, 0], H[2, 0]) - alpha * (v0 - v3)
    g1 = (1.0 - beta) * wp.vec3(H[0, 1], H[1, 1], H[2, 1]) - alpha * (v1 - v3)
    g2 = (1.0 - beta) * wp.vec3(H[0, 2], H[1, 2], H[2, 2]) - alpha * (v2 - v3)
    return g0, g1, g2


@wp.func
def layered_tet_forces(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3, v0: wp.vec3, v1: wp.vec3,
                       v2: wp.vec3, v3: wp.vec3, B: wp.mat33, mu: float, lam: float, shell_ratio: float,
                       shell: float, alpha: float, beta: float):
    """`tet_forces` of a layered tet: moduli scaled by 1 + (ratio - 1) * its shell fraction (mu and
    lambda alike, so nu is kept). Shared by the streamed and the frame-resident layered kernels."""
    scale = 1.0 + (shell_ratio - 1.0) * shell
    return tet_forces(x0, x1, x2, x3, v0, v1, v2, v3, B, scale * mu, scale * lam, alpha, beta)


@wp.kernel
def eval_elastic_forces(
    x: wp.array[wp.vec3],
    v: wp.array[wp.vec3],
    tets: wp.array2d[wp.int32],
    dm_inv: wp.array[wp.mat33],
    env_mu: wp.array[float],
    env_lam: wp.array[float],
    n_tets: int,
    n_nodes: int,
    alpha: float,
    beta: float,
    n_slots: int,
    gather: int,
    f: wp.array[wp.vec3],
    fs: wp.array[wp.vec3],
):
    tid = wp.tid()
    env = tid // n_tets
    t = tid - env * n_tets
    off = env * n_nodes
    i0 = tets[t, 0] + off
    i1 = tets[t, 1] + off
    i2 = tets[t, 2] + off
    i3 = tets[t, 3] + off
    g0, g1, g2 = tet_forces(x[i0], x[i1], x[i2], x[i3], v[i0], v[i1], v[i2], v[i3], dm_inv[t],
                            env_mu[env], env_lam[env], alpha, beta)
    deposit_forces(f, fs, t, env * n_slots, i0, i1, i2, i3, g0, g1, g2, gather)


@wp.kernel
def eval_elastic_forces_layered(
    x: wp.array[wp.vec3],
    v: wp.array[wp.vec3],
    tets: wp.array2d[wp.int32],
    dm_inv: wp.array[wp.mat33],
    env_mu: wp.array[float],
    env_lam: wp.array[float],
    tet_shell: wp.array[float],
    env_shell_ratio: wp.array[float],
    env_alpha: wp.array[float],
    n_tets: int,
    n_nodes: int,
    beta: float,
    n_slots: int,
    gather: int,
    f: wp.array[wp.vec3],
    fs: wp.array[wp.vec3],
):
    """`eval_elastic_forces` with a stiffer outer shell and a per-env damping alpha (residual loop).

    A tet's moduli are scaled by 1 + (ratio - 1) * shell fraction (`layered_tet_forces`). At ratio 1
    and alpha equal to the config's, the result equals the reference kernel's bit for bit (the scale
    is exactly 1.0).
    """
    tid = wp.tid()
    env = tid // n_tets
    t = tid - env * n_tets
    off = env * n_nodes
    i0 = tets[t, 0] + off
    i1 = tets[t, 1] + off
    i2 = tets[t, 2] + off
    i3 = tets[t, 3] + off
    g0, g1, g2 = layered_tet_forces(x[i0], x[i1], x[i2], x[i3], v[i0], v[i1], v[i2], v[i3], dm_inv[t],
                                    env_mu[env], env_lam[env], env_shell_ratio[env], tet_shell[t],
                                    env_alpha[env], beta)
    deposit_forces(f, fs, t, env * n_slots, i0, i1, i2, i3, g0, g1, g2, gather)


def force_slots(tets: np.ndarray, needs_force: np.ndarray, n_nodes: int,
                run_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gather lists: for each node that needs its force, the fs slots (4 run_index[t] + corner) of
    its (tet, corner) pairs in mesh order, the order a CPU scatter adds them, so both sums match
    bit for bit whatever order the tets run in. Returns the slots and per node [start[i], start[i+1])."""
    node = tets.reshape(-1)
    slot = (4 * np.repeat(np.asarray(run_index), 4) + np.tile(np.arange(4), len(tets))).astype(np.int32)
    idx = np.flatnonzero(needs_force[node])
    order = idx[np.argsort(node[idx], kind="stable")]  # by node, then (tet, corner) in mesh order
    start = np.concatenate([[0], np.cumsum(np.bincount(node[idx], minlength=n_nodes))]).astype(np.int32)
    return slot[order], start


def lame_parameters(E, nu, mode: str = "standard") -> tuple[np.ndarray, np.ndarray]:
    """(mu, lambda) per env. "smith" rescales them so that the small-strain moduli equal E, nu.

    Linearised at F = I the stable Neo-Hookean gives mu_eff = 0.75 mu and lambda_eff =
    lambda - 0.625 mu; "smith" (mu' = 4/3 mu, lambda' = lambda + 5/6 mu) undoes that.
    """
    E, nu = np.asarray(E, np.float64), np.asarray(nu, np.float64)
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    if mode == "smith":
        mu, lam = 4.0 / 3.0 * mu, lam + 5.0 / 6.0 * mu
    elif mode != "standard":
        raise ValueError(f"material.lame={mode!r}: use 'standard' or 'smith'")
    return mu, lam


def effective_youngs_modulus(E, nu, mode: str = "standard") -> np.ndarray:
    """Small-strain Young's modulus the discrete material actually has (see lame_parameters)."""
    mu, lam = lame_parameters(E, nu, mode)
    mu_e, lam_e = 0.75 * mu, lam - 0.625 * mu
    return mu_e * (3 * lam_e + 2 * mu_e) / (lam_e + mu_e)


def rest_shape(nodes: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dm^-1 (T, 3, 3) with Dm = [x0-x3, x1-x3, x2-x3], and rest volumes (T,), float64."""
    x = nodes[tets]
    dm = np.stack([x[:, 0] - x[:, 3], x[:, 1] - x[:, 3], x[:, 2] - x[:, 3]], axis=2)
    det = np.linalg.det(dm)
    if np.any(np.abs(det) < 1e-18):
        raise ValueError(f"mesh has {np.sum(np.abs(det) < 1e-18)} degenerate tets (zero volume)")
    return np.linalg.inv(dm), np.abs(det) / 6.0


def lumped_mass(nodes: np.ndarray, tets: np.ndarray, rho: float, mass_scale: float = 1.0) -> np.ndarray:
    """rho * V / 4 per tet node (rest volume), times mass_scale; (N,) float64."""
    _, vol = rest_shape(nodes, tets)
    m = np.zeros(len(nodes))
    np.add.at(m, tets.reshape(-1), np.repeat(vol * rho / 4.0, 4))
    return m * mass_scale


def strain_energy(nodes: np.ndarray, x: np.ndarray, tets: np.ndarray, mu: float, lam: float) -> float:
    """Total stable Neo-Hookean energy with rest volumes (numpy, float64; for tests and checks)."""
    dm_inv, vol = rest_shape(nodes, tets)
    p = x[tets]
    ds = np.stack([p[:, 0] - p[:, 3], p[:, 1] - p[:, 3], p[:, 2] - p[:, 3]], axis=2)
    F = ds @ dm_inv
    ic = np.einsum("tij,tij->t", F, F)
    alpha = 1.0 + 0.75 * mu / lam
    psi = (0.5 * mu * (ic - 3.0) - 0.5 * mu * np.log((ic + 1.0) / 4.0)
           + 0.5 * lam * (np.linalg.det(F) - alpha) ** 2)
    psi -= 0.5 * lam * (1.0 - alpha) ** 2  # zero at rest
    return float((vol * psi).sum())


def courant_dt(nodes: np.ndarray, tets: np.ndarray, E: float, nu: float, rho: float,
               mass_scale: float = 1.0, mode: str = "standard") -> float:
    """Explicit stability estimate min over tets of h / c_p, h = the smallest tet altitude.

    c_p = sqrt((lambda_eff + 2 mu_eff) / (rho * mass_scale)). A rule of thumb for the undamped
    limit; docs/twin.md compares it with the measured stable dt.
    """
    mu, lam = lame_parameters(E, nu, mode)
    c_p = np.sqrt((lam - 0.625 * mu + 1.5 * mu) / (rho * mass_scale))
    x = nodes[tets]
    vol = np.abs(np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])) / 6
    faces = [(1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2)]
    area = np.max([0.5 * np.linalg.norm(np.cross(x[:, b] - x[:, a], x[:, c] - x[:, a]), axis=1)
                   for a, b, c in faces], axis=0)
    return float(np.min(3.0 * vol / area) / c_p)


def elastic_forces(nodes: np.ndarray, tets: np.ndarray, x: np.ndarray, v: np.ndarray | None = None,
                   mu: float = 1.0, lam: float = 1.0, alpha: float = 0.0, beta: float = 0.0,
                   device: str = "cpu") -> np.ndarray:
    """Nodal forces (N, 3) of one configuration x through the kernel (allocates: tests, checks)."""
    dm_inv, _ = rest_shape(nodes, tets)
    v = np.zeros_like(x) if v is None else v
    f = wp.zeros(len(x), dtype=wp.vec3, device=device)
    no_fs = wp.zeros(1, dtype=wp.vec3, device=device)
    wp.launch(eval_elastic_forces, dim=len(tets), device=device,
              inputs=[wp.array(x, dtype=wp.vec3, device=device), wp.array(v, dtype=wp.vec3, device=device),
                      wp.array(tets, dtype=wp.int32, device=device),
                      wp.array(dm_inv, dtype=wp.mat33, device=device),
                      wp.array([mu], dtype=float, device=device), wp.array([lam], dtype=float, device=device),
                      len(tets), len(x), alpha, beta, 0, 0], outputs=[f, no_fs])
    return f.numpy().astype(np.float64)
