"""selftest.remake_set: one run of a self-test re-made exactly from the seed, alone (toy simulator, no twin)."""

import numpy as np
import pytest

from palpation.loop.config import LoopConfig, SelftestConfig
from palpation.loop.inputs import load_targets
from palpation.loop.problem import initial_params
from palpation.loop.selftest.fixed import draw_injections, make_sets, remake_set, simulate_injections
from palpation.markers.template import rest_template
from palpation.measured import load_measured_set, make_measured_set
from tests.loop.selftest.test_fixed import STATES

REST = rest_template().astype(np.float64)


def simulate(jobs):
    """Markers that depend on every parameter of the job (so a wrong injection shows)."""
    out = [REST + 1e-6 * sum(np.sin(i + 1.0) * v for i, v in enumerate(p.values())) + 0.3 * (s.depth_mm or 0.0)
           for s, p in jobs]
    return np.stack(out), np.zeros(len(jobs), bool)


def test_a_run_is_remade_exactly_after_out_of_list_draws(tmp_path):
    # the marker defect draws from the generator in the runs before the camera ones: remake_set replays those draws
    cfg = LoopConfig(selftest=SelftestConfig(cases=["unlisted:marker_defect", "camera"], runs_per_case=2, seed=3,
                                             states=["press", "twist_x"], holdout=["twist_x"])).validate()
    rest = REST.astype(np.float32)
    template = load_targets(make_measured_set(np.stack([rest, rest]), np.ones((2, 127), bool), rest, STATES),
                            "geometry", [], cfg.selftest.states)
    geometry = {s.name: s for s in STATES}
    base = initial_params({"E": 1.2225e6})
    rng = np.random.default_rng(cfg.selftest.seed)
    injections = draw_injections(cfg, base, rng)
    markers = simulate_injections(injections, template, simulate, cfg, base)
    paths = make_sets(injections, markers, template, cfg.selftest.noise_px, rng, tmp_path, geometry, rest)
    for run in (1, 3):
        inj, mset = remake_set(cfg, base, template, simulate, run, geometry, rest)
        saved = load_measured_set(paths[run])
        np.testing.assert_allclose(mset.markers, saved.markers, rtol=0, atol=1e-4)
        assert inj.run == run and inj.label == ("unlisted:marker_defect" if run < 2 else "camera")
    with pytest.raises(ValueError, match="self-test run 4: this configuration has runs 0..3"):
        remake_set(cfg, base, template, simulate, 4, geometry, rest)


def test_a_diverged_run_is_redrawn_in_its_slice_and_remade_the_same(tmp_path):
    """Strong draws can leave the twin's stable range (seeds 3-6 of the 60-run self-test): that run alone is drawn
    again from its own stream, in its strength slice; the other runs and the generator's sequence do not move."""
    cfg = LoopConfig(selftest=SelftestConfig(cases=["viscous", "camera"], runs_per_case=2, seed=3,
                                             states=["press", "twist_x"], holdout=["twist_x"])).validate()
    rest = REST.astype(np.float32)
    template = load_targets(make_measured_set(np.stack([rest, rest]), np.ones((2, 127), bool), rest, STATES),
                            "geometry", [], cfg.selftest.states)
    base = initial_params({"E": 1.2225e6})
    first = draw_injections(cfg, base, np.random.default_rng(cfg.selftest.seed))

    def unstable(jobs):  # run 1 (viscous, its top strength slice) diverges on its first draw
        markers, failed = simulate(jobs)
        return markers, failed | np.array([p == first[1].params for _, p in jobs])

    injections = draw_injections(cfg, base, np.random.default_rng(cfg.selftest.seed))
    markers = simulate_injections(injections, template, unstable, cfg, base)
    assert [i.redrawn for i in injections] == [0, 1, 0, 0] and markers.shape == (4, 2, 127, 2)
    assert 1.75 <= injections[1].strengths["viscous"] <= 2.5 and injections[1].params != first[1].params
    assert all(a.params == b.params for a, b in zip(injections, first) if a.run != 1)
    inj, _ = remake_set(cfg, base, template, unstable, 1, {s.name: s for s in STATES}, rest)
    assert inj.params == injections[1].params and inj.redrawn == 1

    def always(jobs):
        markers, failed = simulate(jobs)
        return markers, np.ones(len(jobs), bool)

    with pytest.raises(ValueError, match=r"run\(s\) \[0, 1, 2, 3\] after 3 redraws"):
        simulate_injections(draw_injections(cfg, base, np.random.default_rng(0)), template, always, cfg, base)
