"""The loop's twin calls: the physics cache and the side-by-side CPU batches change no bit (coarse mesh, a few
frames per env)."""

import os

import numpy as np

from palpation.loop.simulate import LoopSimulator, State, loop_twin_config
from palpation.markers.template import rest_template
from palpation.twin.config import TwinConfig
from palpation.twin.mesh import cached_sensor_mesh

PRESS = State("press_d4", "press", 4.0)
TWIST = State("twist_x_d2", "twist_x", 2.0, 20.0)


def _sim(**kw) -> LoopSimulator:
    mesh = cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))
    return LoopSimulator(mesh, loop_twin_config(TwinConfig(), 1.5e-3), rest_template(), device="cpu",
                         max_frames=6, **kw)


def _jobs() -> list:
    base = {"E": 1.2e6}
    return [(PRESS, base), (TWIST, base), (PRESS, {"E": 2.0e6}), (PRESS, {**base, "cam_dx_px": 3.0}),
            (TWIST, {"E": 9.0e5, "k_s": 2000.0}), (PRESS, {"E": 1.5e6, "mount_dz_mm": 0.2}), (TWIST, {"E": 2.0e6})]


def test_workers_and_cache_change_no_bit():
    jobs = _jobs()
    plain = _sim(workers=1, cache_bytes=0)
    ref, ref_bad = plain.simulate(jobs)
    assert plain.envs_simulated == 6 and plain.cache_hits == 0  # the camera job shares its env
    fast = _sim(workers=2)
    first, bad = fast.simulate(jobs[:3])
    m, m_bad = fast.simulate(jobs)  # three envs read back, three run in two threads per kind
    assert fast.envs_simulated == 6 and fast.cache_hits == 3
    # each of its calls: three parts of one env (6 frames) on two worker threads, 12 env-frames on the busier
    # (18 only if one thread ran two parts before the other took one: the span is what the pool did)
    assert plain.env_frames == plain.span_frames == 36 and fast.env_frames == 36
    assert 2 * 12 <= fast.span_frames < fast.env_frames
    assert fast.cached_frames == 18 and plain.cached_frames == 0
    np.testing.assert_array_equal(first, ref[:3])
    np.testing.assert_array_equal(m, ref)
    np.testing.assert_array_equal(m_bad, ref_bad)
    assert np.isfinite(ref).all() and not ref_bad.any()
    assert np.abs(ref[0] - ref[2]).max() > 0  # the parameters reach the markers (the test can fail)


def test_pooled_twins_change_no_bit(monkeypatch):
    """Calls of as many envs as an earlier one run on its twin (reset, new parameters, its graph replayed):
    the same markers as a twin built per call."""
    jobs = _jobs()
    calls = [jobs[:3], jobs[3:6], [jobs[6], jobs[0], jobs[4]], jobs[1:3]]
    pooled = _sim(workers=1, cache_bytes=0, split_by_kind=False)  # one batch a call, as on a GPU
    got = [pooled.simulate(c) for c in calls]
    assert sorted(t.n_envs for t in pooled._twins) == [2, 3]  # three calls of 3 envs, one twin
    monkeypatch.setattr("palpation.loop.simulate.IDLE_TWINS", 0)  # nothing kept: a twin built per call
    built = _sim(workers=1, cache_bytes=0, split_by_kind=False)
    for c, (m, bad) in zip(calls, got):
        ref, ref_bad = built.simulate(c)
        np.testing.assert_array_equal(m, ref)
        np.testing.assert_array_equal(bad, ref_bad)
    assert not built._twins


def test_cache_is_bounded():
    sim = _sim(workers=1, cache_bytes=1)  # too small for one env: nothing kept, results still come
    sim.simulate(_jobs()[:2])
    sim.simulate(_jobs()[:2])
    assert sim.cache_hits == 0 and sim.envs_simulated == 4 and not sim._cache
