"""Vessel SDF and penalty contact: force along the SDF normal, zero outside, damping, friction."""

import numpy as np
import pytest
import warp as wp

from palpation.twin.contact import ContactParams, eval_contact_forces, vessel_sdf

DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])
CENTER, HALF, RADIUS, TOP = np.array([0.039, 0.039, 0.012]), 0.02, 0.002, 0.015


@wp.kernel
def sdf_kernel(p: wp.array[wp.vec3], c: wp.vec3, h: float, r: float, d: wp.array[float],
               n: wp.array[wp.vec3]):
    i = wp.tid()
    di, ni = vessel_sdf(p[i], c, h, r)
    d[i] = di
    n[i] = ni


def sdf(points, device):
    p = wp.array(points, dtype=wp.vec3, device=device)
    d = wp.zeros(len(points), dtype=float, device=device)
    n = wp.zeros(len(points), dtype=wp.vec3, device=device)
    wp.launch(sdf_kernel, dim=len(points), inputs=[p, wp.vec3(*CENTER), HALF, RADIUS], outputs=[d, n],
              device=device)
    return d.numpy(), n.numpy()


def contact(x, v, device, n_envs=1, k_n=1000.0, c_n=0.0, k_t=0.0, mu=0.0, vessel=1, phantom=0,
            k_s=500.0):
    """Launch eval_contact_forces with every point a surface node; returns (f_c, flags)."""
    x = np.asarray(x, float).reshape(n_envs, -1, 3)
    N = x.shape[1]
    p = ContactParams()
    for key, val in dict(k_n=k_n, c_n=c_n, k_t=k_t, mu=mu, k_s=k_s, c_s=0.0).items():
        setattr(p, key, wp.array(np.full(n_envs, val), dtype=float, device=device))
    p.vessel = wp.array(np.broadcast_to(vessel, n_envs).astype(np.int32), dtype=wp.int32, device=device)
    p.vessel_center, p.vessel_half_length, p.vessel_radius = wp.vec3(*CENTER), HALF, RADIUS
    p.phantom_top_z, p.phantom_on, p.slip_eps = TOP, phantom, 1e-6
    vec = lambda a: wp.array(np.asarray(a, float).reshape(-1, 3), dtype=wp.vec3, device=device)  # noqa: E731
    f_c = wp.zeros(n_envs * N, dtype=wp.vec3, device=device)
    flags = wp.zeros(n_envs, dtype=wp.int32, device=device)
    wp.launch(eval_contact_forces, dim=n_envs * N, device=device,
              inputs=[vec(x), vec(np.broadcast_to(v, x.shape)), vec(np.zeros(x.shape)),
                      wp.ones(N, dtype=float, device=device),
                      wp.array(np.arange(N), dtype=wp.int32, device=device), N, N, 0.0, p, 1],
              outputs=[f_c, flags])
    return f_c.numpy().reshape(n_envs, N, 3).astype(float), flags.numpy()


@pytest.mark.parametrize("device", DEVICES)
def test_sdf_of_finite_cylinder(device):
    pts = CENTER + np.array([[0, 0, 0.003], [0, -0.0015, 0], [0.019, 0, 0.0005], [0.025, 0, 0],
                             [0.023, 0.006, 0], [0, 0, 0]])
    d, n = sdf(pts, device)
    np.testing.assert_allclose(d, [0.001, -0.0005, -0.001, 0.005, 0.005, -0.002], atol=1e-7)
    np.testing.assert_allclose(n[:4], [[0, 0, 1], [0, -1, 0], [1, 0, 0], [1, 0, 0]], atol=1e-6)
    np.testing.assert_allclose(n[4], [0.6, 0.8, 0], atol=1e-6)  # off the rim: toward the edge
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)


@pytest.mark.parametrize("device", DEVICES)
def test_force_along_normal_and_zero_outside(device):
    dirs = np.array([[0, 0, 1], [0, 0.6, 0.8], [0, -1, 0]])
    depth = np.array([0.5e-3, 0.2e-3, 1e-3])
    inside = CENTER + dirs * (RADIUS - depth)[:, None] + [[0.005, 0, 0]]
    outside = CENTER + dirs * (RADIUS + 1e-4)
    f, flags = contact(np.vstack([inside, outside]), np.zeros(3), device, k_n=1000.0)
    np.testing.assert_allclose(f[0, :3], 1000.0 * depth[:, None] * dirs, rtol=1e-4, atol=1e-7)
    assert np.all(f[0, 3:] == 0.0) and flags[0] == 1
    f, flags = contact(outside, np.zeros(3), device)
    assert np.all(f == 0.0) and flags[0] == 0


@pytest.mark.parametrize("device", DEVICES)
def test_damping_scales_with_closing_speed_and_depth(device):
    x = CENTER + [0, 0, RADIUS - 1e-3]
    closing, _ = contact(x, [0, 0, -0.2], device, k_n=1000.0, c_n=100.0)
    opening, _ = contact(x, [0, 0, 0.2], device, k_n=1000.0, c_n=100.0)
    assert closing[0, 0, 2] == pytest.approx((1000.0 + 100.0 * 0.2) * 1e-3, rel=1e-5)
    assert opening[0, 0, 2] == pytest.approx(1000.0 * 1e-3, rel=1e-5)  # no pull when separating


@pytest.mark.parametrize("device", DEVICES)
def test_tangential_force_viscous_then_coulomb(device):
    x = CENTER + [0, 0, RADIUS - 1e-3]  # |F_n| = 1 N
    slow, _ = contact(x, [0.001, 0, 0], device, k_n=1000.0, k_t=100.0, mu=0.5)
    fast, _ = contact(x, [0.1, 0, 0], device, k_n=1000.0, k_t=100.0, mu=0.5)
    np.testing.assert_allclose(slow[0, 0], [-0.1, 0, 1.0], rtol=1e-5)  # k_t |v_t|
    np.testing.assert_allclose(fast[0, 0], [-0.5, 0, 1.0], rtol=1e-5)  # capped at mu |F_n|
    none, _ = contact(x, [0.1, 0, 0], device, k_n=1000.0)
    assert none[0, 0, 0] == 0.0  # reference: k_t = mu = 0


@pytest.mark.parametrize("device", DEVICES)
def test_phantom_half_space_and_per_env_vessel_switch(device):
    x = np.array([[CENTER + [0, 0, RADIUS - 1e-3], [0.0, 0.0, TOP - 2e-4]]] * 2)
    f, flags = contact(x, np.zeros(3), device, n_envs=2, vessel=np.array([1, 0]), phantom=1, k_s=500.0)
    np.testing.assert_allclose(f[:, 1], [[0, 0, 0.1], [0, 0, 0.1]], rtol=1e-4)  # 500 N/m * 0.2 mm
    # node 0 is 1 mm inside the vessel and 2 mm below the phantom top: env 1 has no vessel
    np.testing.assert_allclose(f[:, 0], [[0, 0, 1.0 + 1.0], [0, 0, 1.0]], rtol=1e-4)
    np.testing.assert_array_equal(flags, [1, 0])  # the flag is the vessel's only
