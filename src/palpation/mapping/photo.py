"""Photo truth for the Silicone map (SPEC §12, §13.6): the phantom photo's vessel polygons on the grid.

The VGG polygons are filled (int32 vertices) on the full rectified photo, which is stretched over the
whole 180 x 100 mm workspace (quirk 19: the phantom is ~212 x 123 mm, so this scales it by ~0.85),
reduced by block majority (area mean > 0.5) to 100 x 180, and ANDed with the swept region: the closing
of `visited` by an L2 disc of radius 2 px. Photo rows/cols map to grid rows/cols directly.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from palpation.paths import PHANTOM
from palpation.readers import one_line, read_image, read_json

PHOTO = PHANTOM / "phantom-uncropped-compressed-undistorted.jpg"
LABELS = PHANTOM / "phantom-labels-vgg.json"
PHOTO_SIZE = (2365, 1377)  # width, height of the rectified photo (used when the photo is not read)
SWEPT_RADIUS_PX = 2


def read_polygons(path: str | Path = LABELS) -> list[np.ndarray]:
    """The annotated `vein` polygons, each (k, 2) float photo px (x right, y down)."""
    path = Path(path)
    fix = "restore data/reference/phantom/phantom-labels-vgg.json from the repository (VGG annotator format)"
    data = read_json(path, fix, "VGG labels", kind=dict)
    polygons = []
    try:
        for entry in data.values():
            regions = entry["regions"]
            for region in (regions.values() if isinstance(regions, dict) else regions):
                shape, label = region["shape_attributes"], region.get("region_attributes", {}).get("label", "vein")
                if shape.get("name") == "polygon" and label == "vein":
                    points = np.stack([shape["all_points_x"], shape["all_points_y"]], 1).astype(np.float64)
                    if points.ndim != 2 or len(points) < 3 or not np.isfinite(points).all():
                        raise ValueError(f"a polygon of {len(points)} points (or not finite)")
                    polygons.append(points)
    except (KeyError, TypeError, AttributeError, ValueError) as exc:
        raise ValueError(f"VGG labels {path}: not the VGG annotator format ({one_line(exc)}); {fix}") from None
    if not polygons:
        raise ValueError(f"VGG labels {path}: no 'vein' polygons found (expected 4); {fix}")
    return polygons


def photo_mask(polygons: list[np.ndarray], size: tuple[int, int] = PHOTO_SIZE) -> np.ndarray:
    """Filled polygons at full photo resolution, (height, width) bool."""
    mask = np.zeros((size[1], size[0]), np.uint8)
    cv2.fillPoly(mask, [p.astype(np.int32) for p in polygons], 1)
    return mask.astype(bool)


def block_majority(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Area mean of `mask` over the blocks of a (rows, cols) grid, > 0.5."""
    mean = cv2.resize(mask.astype(np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
    return mean > 0.5


def disc(radius: float) -> np.ndarray:
    """L2 disc structuring element: offsets with |d| <= radius."""
    r = int(np.floor(radius))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return (xx ** 2 + yy ** 2) <= radius ** 2


def swept_region(visited: np.ndarray, radius: float = SWEPT_RADIUS_PX) -> np.ndarray:
    """Binary closing of the visited pixels by an L2 disc; OpenCV's default border is neutral, so the
    grid edge neither grows nor erodes the region."""
    closed = cv2.morphologyEx(np.asarray(visited, np.uint8), cv2.MORPH_CLOSE, disc(radius).astype(np.uint8))
    return closed.astype(bool)


def photo_truth(visited: np.ndarray, polygons: list[np.ndarray] | None = None,
                size: tuple[int, int] = PHOTO_SIZE) -> np.ndarray:
    """Photo truth on the grid of `visited` (H, W): block-majority polygons AND the swept region."""
    polygons = read_polygons() if polygons is None else polygons
    full = photo_mask(polygons, size)
    return block_majority(full, visited.shape) & swept_region(visited)


def photo_size(path: str | Path = PHOTO) -> tuple[int, int]:
    """(width, height) of the rectified photo; the shipped constant if the file is absent (a damaged one is refused)."""
    path = Path(path)
    if not path.exists():
        return PHOTO_SIZE
    image = read_image(path, "restore it from data/reference/phantom/ (the repository ships it)", "phantom photo")
    return image.shape[1], image.shape[0]
