"""Prediction-viewer panels: colour classes, dot detection on synthetic images, a few real states."""

import cv2
import numpy as np
import pytest

from palpation.paths import VIDEOS
from palpation.realdata.panels import (
    PANEL_CROPS,
    classify_colours,
    count_states,
    crop_panel,
    detect_dots,
    iter_state_frames,
    read_states,
    state_frame,
)

MEAT_VIDEO = VIDEOS / "predictions_sim_to_meat.mp4"
MAGENTA, CYAN = (230, 20, 230), (230, 230, 20)  # BGR


def synthetic_panel(centres, colours, size=404, seed=0):
    """Black panel with filled dots, JPEG-like noise and a few stray coloured pixels."""
    img = np.zeros((size, size, 3), np.uint8)
    for (x, y), c in zip(centres, colours):
        cv2.circle(img, (int(x), int(y)), 3, c, -1)
    rng = np.random.default_rng(seed)
    img = np.clip(img.astype(int) + rng.integers(-15, 16, img.shape), 0, 255).astype(np.uint8)
    img[5, 5] = MAGENTA  # a single stray pixel is speckle, not a dot
    return img


def test_classify_colours_thresholds():
    px = np.array([[[200, 50, 200], [200, 200, 50], [200, 120, 200], [140, 200, 50], [0, 0, 0],
                    [255, 255, 255]]], np.uint8)  # BGR
    assert classify_colours(px).tolist() == [[1, 0, -1, -1, -1, -1]]


def test_detect_dots_on_synthetic_panel():
    centres = [(40 + 22 * i, 60 + 30 * j) for i in range(10) for j in range(8)]
    colours = [MAGENTA if (i + j) % 3 == 0 else CYAN for i in range(10) for j in range(8)]
    dots = detect_dots(synthetic_panel(centres, colours))
    assert len(dots.xy) == len(centres)
    order = np.lexsort((dots.xy[:, 1], dots.xy[:, 0]))
    np.testing.assert_allclose(dots.xy[order], np.array(centres, float), atol=0.3)
    expected = np.array([c == MAGENTA for c in colours], np.int8)
    np.testing.assert_array_equal(dots.labels[order], expected)


def test_crop_panel_by_name_and_tuple():
    frame = np.arange(960 * 1280 * 3, dtype=np.uint32).reshape(960, 1280, 3)
    a = crop_panel(frame, "hard_prediction")
    b = crop_panel(frame, PANEL_CROPS["hard_prediction"])
    assert a.shape[:2] == (404, 403)
    np.testing.assert_array_equal(a, b)
    assert state_frame(0) == 2 and state_frame(10) == 52


def test_real_meat_states():
    """Frame 5s + 2 of the Meat viewer: 127 dots in both panels, sane label counts."""
    assert count_states(MEAT_VIDEO) == 219
    panels = read_states(MEAT_VIDEO, ["ground_truth", "hard_prediction"], states=[0, 30, 185])
    for dots in panels["ground_truth"] + panels["hard_prediction"]:
        assert len(dots.xy) == 127
    n_pos = [int(d.labels.sum()) for d in panels["ground_truth"]]
    assert n_pos == [0, 18, 38]  # trial 1 start, mid trial 2, the 3-straw peak
    # the reference model's hard predictions (threshold 0.58): none, many, all
    assert [int(d.labels.sum()) for d in panels["hard_prediction"]] == [0, 83, 127]


def test_seek_matches_sequential_read():
    seq = dict(iter_state_frames(MEAT_VIDEO, states=range(0, 13)))
    jumped = dict(iter_state_frames(MEAT_VIDEO, states=[12]))
    np.testing.assert_array_equal(seq[12], jumped[12])


def test_missing_video(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.mp4"):
        read_states(tmp_path / "nope.mp4", ["ground_truth"])


def test_not_a_video(tmp_path):
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video")
    with pytest.raises(ValueError, match="bad.mp4"):
        count_states(bad)


def test_state_out_of_range():
    with pytest.raises(ValueError, match="out of range"):
        next(iter_state_frames(MEAT_VIDEO, states=[219]))
