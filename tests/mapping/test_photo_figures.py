"""Photo truth on the grid, confusion colours, Table 4 Markdown."""

import numpy as np
import pandas as pd

from palpation.mapping.figures import COLOURS, confusion_rgb, save_rgb, tile
from palpation.mapping.photo import block_majority, photo_mask, photo_truth, read_polygons, swept_region
from palpation.mapping.table import COLUMNS, table4_markdown
from palpation.mapping.threshold import OperatingPoint


def test_shipped_polygons_fill_to_four_vessels():
    polys = read_polygons()
    assert len(polys) == 4
    grid = block_majority(photo_mask(polys), (100, 180))
    assert 0.05 < grid.mean() < 0.2  # four ~4 mm wide vessels over the workspace
    assert not grid[:, 165:].any()  # the photo's right strip has no vessel: path 4 sweeps there


def test_block_majority_threshold():
    m = np.zeros((10, 20), bool)
    m[:6, :] = True  # 60 % of the top block row
    assert block_majority(m, (1, 2)).tolist() == [[True, True]]
    m[:] = False
    m[:5, :] = True  # exactly half is not a majority
    assert block_majority(m, (1, 2)).tolist() == [[False, False]]


def test_swept_region_closes_small_gaps_and_keeps_borders():
    v = np.zeros((12, 12), bool)
    v[:, :5] = True
    v[:, 6:] = True  # a 1 px column never visited
    closed = swept_region(v)
    assert closed.all()
    photo = photo_truth(np.zeros((100, 180), bool))
    assert not photo.any()  # nothing swept, nothing true


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


def test_markdown_puts_the_paper_beside_ours():
    op = OperatingPoint(0.61, "precision>=0.9@3mm", 0.9, 0.3, 0.45, 100, 3.0, 0.9, 20)
    row = {"config": "A-to-B", "threshold": op.threshold, "threshold_rule": op.rule, "tp": 10, "fp": 2, "fn": 5,
           "tn": 100, "mcc": 0.5, "f1": 0.6, "precision": 0.8, "recall": 0.6, "fg_iou": 0.5, "bg_iou": 0.9,
           "ap": 0.7, "d_bar_mm": 1.234}
    text = table4_markdown(pd.DataFrame([row], columns=list(COLUMNS)), "quick", ["a note"])
    assert "| A-to-B | ours |" in text and "| A-to-B | paper |" in text
    assert "**1.23**" in text and "**1.21**" in text and "0.5739" in text and "* a note" in text
