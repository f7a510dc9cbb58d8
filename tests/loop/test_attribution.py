"""Attribution: the injected signature is named, sign constraints hold, pure noise names nothing."""

import numpy as np
import pytest

from palpation.loop.attribution import Signature, attribute, fit_subset


@pytest.fixture
def sigs():
    rng = np.random.default_rng(3)
    n = 600
    return [Signature("a", ["a"], rng.normal(size=(n, 1)), [True]),
            Signature("b", ["b0", "b1"], rng.normal(size=(n, 2)), [False, False]),
            Signature("c", ["c"], rng.normal(size=(n, 1)), [True])]


def test_names_the_effect_that_made_the_residual(sigs):
    rng = np.random.default_rng(4)
    needed = 2.0 * sigs[1].columns[:, 0] - 0.5 * sigs[1].columns[:, 1] + rng.normal(0, 0.1, 600)
    att = attribute(-needed, sigs)  # residual = sim - real = -(what the twin misses)
    assert att.named == "b" and att.best_subset == ["b"]
    assert att.betas["b"]["b0"] == pytest.approx(2.0, abs=0.05)
    assert att.ranking[0]["effect"] == "b" and att.ranking[0]["share"] > 0.95


def test_nonnegative_dofs_cannot_go_backwards(sigs):
    beta, rss = fit_subset(-3.0 * sigs[0].columns[:, 0], [sigs[0]])
    assert beta[0] == 0.0 and rss == pytest.approx(float(np.sum((3.0 * sigs[0].columns) ** 2)))


def test_noise_alone_names_nothing_and_dead_columns_stay_zero(sigs):
    rng = np.random.default_rng(5)
    dead = Signature("dead", ["d"], np.full((600, 1), 1e-9), [False])
    att = attribute(rng.normal(size=600), [*sigs, dead])
    assert att.named is None and att.best_subset == []
    assert att.betas["dead"]["d"] == 0.0
    with pytest.raises(ValueError, match="not finite"):
        attribute(np.full(600, np.nan), sigs)
