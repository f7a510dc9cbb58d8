"""Fig. 7 pieces: confusion colours, tiling, the enlarged PNG."""

import numpy as np

from palpation.figures.maps import COLOURS, confusion_rgb, save_rgb, tile


def test_confusion_colours_and_tiling():
    pred = np.array([[1, 1], [0, 0]], bool)
    truth = np.array([[1, 0], [1, 0]], bool)
    rgb = confusion_rgb(pred, truth)
    assert tuple(rgb[0, 0]) == COLOURS["tp"] and tuple(rgb[0, 1]) == COLOURS["fp"]
    assert tuple(rgb[1, 0]) == COLOURS["fn"] and tuple(rgb[1, 1]) == (0, 0, 0)
    mosaic = tile([rgb] * 7, gap=1, per_row=5)
    assert mosaic.shape == (2 * 2 + 1, 5 * 2 + 4, 3)


def test_big_png_is_five_times(tmp_path):
    import matplotlib.image as mpimg

    rgb = confusion_rgb(np.eye(3, dtype=bool), np.eye(3, dtype=bool))
    out = save_rgb(rgb, tmp_path / "m_big.png", 5)
    assert mpimg.imread(out).shape[:2] == (15, 15)
