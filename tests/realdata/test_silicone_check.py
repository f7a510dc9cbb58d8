"""Cross-check of Silicone labels against the prediction viewer's Ground Truth panel."""

import cv2
import numpy as np
import pytest

from palpation.markers.lattice import ideal_hex_lattice
from palpation.realdata import silicone as sil
from palpation.realdata import silicone_check as chk


def test_annotation_state_mapping():
    assert chk.annotation_state(0) == 2  # trial 1, central frame 1 -> video 1 frame 3
    assert chk.annotation_state(11) == 13
    assert chk.annotation_state(12) == 18  # trial 2 starts at video 2 frame 3
    assert chk.annotation_state(119) == 16 * 9 + 13
    with pytest.raises(ValueError, match="viewer state"):
        chk.annotation_state(120)


def _synthetic_viewer(points, labels):
    """A 1280x960 black viewer frame with magenta/cyan dots at panel `points` in the GT panel."""
    frame = np.zeros((960, 1280, 3), np.uint8)
    y0, _, x0, _ = chk.GT_PANEL
    for (x, y), lab in zip(points, labels):
        bgr = (255, 0, 255) if lab == 1 else (255, 255, 0)
        cv2.circle(frame, (int(round(16 * (x + x0))), int(round(16 * (y + y0)))), 16 * 3, bgr, -1, shift=4)
    return frame


def test_panel_dots_and_registration_recover_labels():
    markers = ideal_hex_lattice(55.0, centre_px=(1040.0, 584.0))  # (127, 2) "sensor" px
    rng = np.random.default_rng(0)
    labels = (rng.random(127) < 0.2).astype(np.int8)
    a = np.radians(2.0)
    rot = 0.409 * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    panel = (markers - markers.mean(0)) @ rot.T + [200.0, 200.0]
    frame = _synthetic_viewer(panel, labels)
    dots, dot_labels = chk.panel_dots(frame)
    assert len(dots) == 127 and dot_labels.sum() == labels.sum()
    index, matrix, residual = chk.register_to_panel(markers, dots)
    assert (index >= 0).all() and residual < 0.3
    assert (dot_labels[index] == labels).all()
    assert np.sqrt(np.linalg.det(matrix[:, :2])) == pytest.approx(0.409, rel=1e-3)


def test_registration_needs_dots():
    with pytest.raises(ValueError, match="ground-truth panel shows 0 dots"):
        chk.register_to_panel(np.zeros((127, 2)), np.zeros((0, 2)))


def test_real_check_first_states():
    """Video 1 frames 1-5 against viewer states 0-2 (video 1 frames 3-5)."""
    data = sil.build_silicone_set(videos=[1], n_frames=5)
    result = chk.check_labels(data["markers"], data["labels"], panel_states=range(3))
    assert result["n_states"] == 3
    assert result["min_agreement"] >= 0.99
    assert all(r["n_panel_dots"] == 127 and r["n_matched"] == 127 for r in result["per_state"])
    assert result["median_residual_panel_px"] < 1.0  # SPEC §13.5: 0.5 px
