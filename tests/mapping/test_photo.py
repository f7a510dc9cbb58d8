"""Photo truth on the grid: the shipped polygons, block majority, the swept region."""

import numpy as np

from palpation.mapping.photo import block_majority, photo_mask, photo_truth, read_polygons, swept_region


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
