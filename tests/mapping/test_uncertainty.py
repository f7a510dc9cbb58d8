"""The seed ensemble on a toy grid (issue 15): per-pixel mean/spread, unsure pixels, coverage-precision."""

import numpy as np
import pytest

from palpation.mapping.grid import Axis, Grid
from palpation.mapping.lift import UNVISITED, MapStack
from palpation.mapping.uncertainty import FN, FP, TN, TP, UNSURE, ensemble_map
from palpation.metrics.ensemble import committed, coverage_curve, ensemble

GRID = Grid(Axis(0, 0.0, 4), Axis(1, 0.0, 5))


def _stack(score):
    score = np.asarray(score, np.float32)[None]
    visited = score > UNVISITED
    truth = np.zeros_like(visited)
    truth[0, 1, :] = True  # the vessel: row 1
    truth &= visited
    return MapStack(GRID, score, visited, truth)


@pytest.fixture
def seeds():
    """3 seed maps: row 1 sure positive, row 3 sure negative, (0, 0) disputed, (2, 4) unvisited."""
    base = np.full((4, 5), 0.1)
    base[1] = 0.9
    maps = [base.copy() for _ in range(3)]
    for m, v in zip(maps, (0.2, 0.8, 0.7)):  # mean 0.567, std 0.32: straddles 0.5
        m[0, 0] = v
    maps[0][1, 0], maps[1][1, 0], maps[2][1, 0] = 0.45, 0.4, 0.44  # a missed vessel pixel, seeds agree
    for m in maps:
        m[2, 4] = UNVISITED
    return [_stack(m) for m in maps]


def test_mean_spread_and_classes(seeds):
    ens = ensemble_map(seeds)
    assert ens.n_seeds == 3 and ens.mean[0, 2, 4] == UNVISITED and ens.spread[0, 2, 4] == 0
    assert ens.mean[0, 0, 0] == pytest.approx(0.5667, abs=1e-4)
    assert ens.spread[0, 0, 0] == pytest.approx(np.std([0.2, 0.8, 0.7], ddof=1), abs=1e-6)
    c = ens.classes()[0]
    assert c[0, 0] == UNSURE and c[1, 1] == TP and c[1, 0] == FN and c[3, 3] == TN and c[2, 4] == -1
    assert ens.unsure.sum() == 1
    rgb = ens.rgb()
    assert rgb.shape == (1, 4, 5, 3) and tuple(rgb[0, 0, 0]) == (255, 200, 0)


def test_coverage_precision_drops_the_unsure_pixel_first(seeds):
    ens = ensemble_map(seeds)
    rows = {r["coverage"]: r for r in ens.coverage_curve(tolerance_px=0.0, coverages=(1.0, 0.9))}
    # at full coverage the disputed pixel (0, 0) is a false positive: 4 TP of 5 predicted
    assert rows[1.0]["precision"] == pytest.approx(4 / 5) and rows[1.0]["recall"] == pytest.approx(4 / 5)
    assert rows[0.9]["precision"] == 1.0 and rows[0.9]["n_pred"] == 4  # it is the least certain pixel
    # with a 1 px tolerance the disputed pixel sits next to the vessel: a hit
    assert ens.coverage_curve(tolerance_px=1.0, coverages=(1.0,))[0]["precision"] == 1.0


def test_marker_ensemble_and_errors():
    mean, spread = ensemble([[0.2, 0.9], [0.4, 0.9]])
    assert np.allclose(mean, [0.3, 0.9]) and np.allclose(spread, [np.sqrt(0.02), 0.0])
    assert np.array_equal(ensemble([[0.3, 0.6]])[1], [0.0, 0.0])  # one seed: no spread
    assert committed(np.array([0.1, 0.3, 0.2, 0.0]), 0.5).tolist() == [False, True, True, False]
    rows = coverage_curve([0.9, 0.8, 0.1], [0.0, 0.0, 0.0], [True, False, False], coverages=(1.0,))
    assert rows[0]["precision"] == 0.5 and rows[0]["recall"] == 1.0
    with pytest.raises(ValueError, match="coverage"):
        committed(np.zeros(3), 0.0)
    other = MapStack(Grid(Axis(0, 0.0, 3), Axis(1, 0.0, 5)), np.zeros((1, 3, 5), np.float32),
                     np.ones((1, 3, 5), bool), np.zeros((1, 3, 5), bool))
    with pytest.raises(ValueError, match="same test samples"):
        ensemble_map([_stack(np.zeros((4, 5))), other])
