"""Ordering unordered detections onto the template: pre-alignment + Hungarian (SPEC §5.2)."""

import numpy as np
import pytest

from palpation.markers.order import (apply_similarity, fit_similarity, match_with_dummy,
                                     order_to_template, similarity_prealign)
from palpation.markers.template import rest_template


def similarity(scale, angle_deg, shift):
    a = np.radians(angle_deg)
    return np.hstack([scale * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]),
                      np.asarray(shift, float)[:, None]])


def test_fit_similarity_recovers_a_transform():
    tpl = rest_template()
    m = similarity(0.6443, 3.0, (21.0, 2.0))
    np.testing.assert_allclose(fit_similarity(tpl, apply_similarity(m, tpl)), m, atol=1e-9)


@pytest.mark.parametrize("scale, angle_deg, shift", [(1.0, 0.0, (0, 0)), (0.6443, 2.0, (21, 2)),
                                                     (1.2, -8.0, (-40, 30))])
def test_order_recovers_shuffled_deformed_markers(scale, angle_deg, shift):
    rng = np.random.default_rng(1)
    tpl = rest_template()
    c = tpl[0]
    # smooth deformation up to ~0.5 spacing (a tilt-like stretch), jitter, shuffle, two glare points
    deformed = tpl + 0.08 * (tpl - c) * ((tpl[:, 1:2] - c[1]) / 300.0) + rng.normal(0, 0.3, tpl.shape)
    truth = apply_similarity(similarity(scale, angle_deg, shift), deformed)
    glare = apply_similarity(similarity(scale, angle_deg, shift), c + np.array([[395, 10], [-5, -398]]))
    perm = rng.permutation(127)
    ordered, found = order_to_template(np.vstack([truth[perm], glare]), tpl)
    assert found.all()
    np.testing.assert_allclose(ordered, truth)


def test_missing_markers_are_nan_and_flagged():
    tpl = rest_template()
    ordered, found = order_to_template(np.delete(tpl, [0, 50, 126], axis=0) + 2.0, tpl)
    assert np.flatnonzero(~found).tolist() == [0, 50, 126]
    assert np.isnan(ordered[~found]).all()
    np.testing.assert_allclose(ordered[found], tpl[found] + 2.0)


def test_similarity_prealign_ignores_a_lattice_phase_shift():
    """Glare on one side pulls the median of the detections; the fit must not lock one step off."""
    tpl = rest_template()
    extra = tpl[0] + np.array([[380.0, y] for y in np.linspace(-150, 150, 12)])
    m = similarity_prealign(tpl, np.vstack([tpl, extra]))
    np.testing.assert_allclose(m, similarity(1.0, 0.0, (0, 0)), atol=1e-6)


def test_match_with_dummy_rejects_far_points():
    target = np.array([[0.0, 0.0], [10.0, 0.0]])
    slot = match_with_dummy(np.array([[0.5, 0.0], [30.0, 0.0], [9.0, 1.0]]), target, dummy_px=5.0)
    assert slot.tolist() == [0, -1, 1]
