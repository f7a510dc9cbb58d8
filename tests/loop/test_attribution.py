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


def test_an_effect_along_a_refitted_column_is_credited_given_that_column():
    """The residual is what a shell leaves once E was fitted: orthogonal to E's column. The shell's signature is
    mostly along E's, so alone it explains little and the BIC leaves it out; held with E's column it explains
    the residual and is named, with its own beta."""
    rng = np.random.default_rng(6)
    n = 600
    e_col = rng.normal(size=n)
    perp = rng.normal(size=n)
    perp -= (perp @ e_col) / (e_col @ e_col) * e_col
    shell = Signature("layered", ["ratio"], (5.0 * e_col + 0.3 * perp)[:, None], [True])
    other = Signature("mount", ["dz"], rng.normal(size=(n, 1)), [False])
    refit = Signature("_refit", ["E"], e_col[:, None], [False])
    needed = 0.3 * perp + rng.normal(0, 0.1, n)  # the twin lacks the shell at beta 1, E took its part along e_col
    plain = attribute(-needed, [shell, other])
    given = attribute(-needed, [shell, other], nuisance=refit)
    assert plain.share_of("layered") < 0.01 and "layered" not in plain.best_subset
    assert given.named == "layered" and given.share_of("layered") > 0.85
    assert given.betas["layered"]["ratio"] == pytest.approx(1.0, abs=0.05)
    assert given.share_of("mount") < 0.05
