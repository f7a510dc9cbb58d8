"""selftest.remake_set: one run of a self-test re-made exactly from the seed, alone (toy simulator, no twin)."""

import numpy as np
import pytest

from palpation.loop.config import LoopConfig, SelftestConfig
from palpation.loop.engine import initial_params
from palpation.loop.inputs import load_targets
from palpation.loop.selftest import draw_injections, make_sets, remake_set
from palpation.markers.template import rest_template
from palpation.measured import load_measured_set, make_measured_set
from tests.loop.test_selftest import STATES

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
    paths = make_sets(draw_injections(cfg, base, rng), template, simulate, cfg.selftest.noise_px, rng, tmp_path,
                      geometry, rest)
    for run in (1, 3):
        inj, mset = remake_set(cfg, base, template, simulate, run, geometry, rest)
        saved = load_measured_set(paths[run])
        np.testing.assert_allclose(mset.markers, saved.markers, rtol=0, atol=1e-4)
        assert inj.run == run and inj.label == ("unlisted:marker_defect" if run < 2 else "camera")
    with pytest.raises(ValueError, match="self-test run 4: this configuration has runs 0..3"):
        remake_set(cfg, base, template, simulate, 4, geometry, rest)
