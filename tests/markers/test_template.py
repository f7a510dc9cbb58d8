"""The 127-marker template and the base-graph order (SPEC §5.2)."""

import numpy as np
import pytest

from palpation.markers.lattice import _bearing_deg
from palpation.markers.template import (N_MARKERS, RING_SIZES, base_graph_order, ideal_hex_lattice,
                                        rest_template, ring6_corners, ring_index, ring_slice)

SPEC_CORNERS = np.array([(1199, 300), (1366, 576), (1211, 858), (888, 868), (720, 592), (874, 301)])


def check_base_graph_properties(points):
    """Ring k is the next 6k by distance from marker 0, sorted by bearing within the ring."""
    dist = np.linalg.norm(points - points[0], axis=1)
    assert dist[0] == 0
    assert np.argmin(np.linalg.norm(points - points.mean(0), axis=1)) == 0
    for ring in range(1, 7):
        inner, this = dist[ring_slice(ring - 1)], dist[ring_slice(ring)]
        assert inner.max() <= this.min()
        assert np.all(np.diff(_bearing_deg(points[ring_slice(ring)] - points[0])) > 0)


def test_ring_layout():
    assert RING_SIZES == (1, 6, 12, 18, 24, 30, 36) and N_MARKERS == 127
    assert np.array_equal(np.bincount(ring_index()), RING_SIZES)
    assert ring_slice(6) == slice(91, 127)
    with pytest.raises(ValueError):
        ring_index(126)


@pytest.mark.parametrize("rotation_deg", [0.0, 7.5, -20.0])
def test_ideal_lattice(rotation_deg):
    lattice = ideal_hex_lattice(55.0, rotation_deg, (1040.0, 584.0))
    assert lattice.shape == (127, 2)
    check_base_graph_properties(lattice)
    np.testing.assert_allclose(lattice[0], [1040, 584])
    nn = np.sort(np.linalg.norm(lattice[:, None] - lattice[None], axis=-1), axis=1)[:, 1]
    np.testing.assert_allclose(nn, 55.0)
    # ring k's farthest points are its 6 corners, at k pitches
    for ring in range(1, 7):
        assert np.isclose(np.linalg.norm(lattice[ring_slice(ring)] - lattice[0], axis=1).max(), 55 * ring)


def test_rest_template_matches_spec():
    tpl = rest_template()
    assert tpl.shape == (127, 2) and np.all(np.isfinite(tpl))
    check_base_graph_properties(tpl)
    assert np.linalg.norm(tpl[0] - [1039, 582]) < 2.5
    err = np.linalg.norm(ring6_corners(tpl) - SPEC_CORNERS, axis=1)
    # four corners within 3 px; the two in the dark vignette (SPEC's hand-placed ones) within 10 px
    assert np.sort(err)[:4].max() < 3.0 and err.max() < 10.0
    assert rest_template() is not rest_template()  # callers get a copy, the cache stays intact


def test_base_graph_order_is_permutation_invariant():
    rng = np.random.default_rng(0)
    points = rest_template() + rng.normal(0, 0.5, (127, 2))
    reference = points[base_graph_order(points)]
    for _ in range(5):
        shuffled = points[rng.permutation(127)]
        np.testing.assert_array_equal(shuffled[base_graph_order(shuffled)], reference)


def test_base_graph_order_rejects_bad_input():
    with pytest.raises(ValueError, match="127"):
        base_graph_order(np.zeros((126, 2)))
    bad = rest_template()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        base_graph_order(bad)
