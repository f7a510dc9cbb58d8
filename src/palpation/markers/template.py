"""The canonical 127-marker template: the markers of `sensor_default_state.png` in base-graph order.

SPEC §5.2 builds the rest template from that photo with the meat-first-run blob detector plus three
hand-placed markers; the ratio detector finds all 127 directly, so nothing is hand-placed here. The
template takes ~0.3 s to compute and is memoised per process.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from palpation.markers.detect import RatioDetector, detect_file
from palpation.markers.lattice import (  # noqa: F401  (re-exported: the template API)
    N_MARKERS,
    N_RINGS,
    RING_INDEX,
    RING_SIZES,
    base_graph_order,
    ideal_hex_lattice,
    median_spacing_px,
    neighbours,
    ring_index,
    ring_slice,
)
from palpation.paths import FLAT_TIP_PHOTOS

REST_PHOTO = FLAT_TIP_PHOTOS / "sensor_default_state.png"


def require_full_set(points: np.ndarray, source: str | os.PathLike) -> np.ndarray:
    """Raise unless exactly 127 markers were found in `source`."""
    if len(points) != N_MARKERS:
        raise ValueError(
            f"{source}: found {len(points)} markers, expected {N_MARKERS}; check the photo (lighting, "
            f"crop) or tune the detector (RatioDetector.ratio_max / area limits)")
    return points


def template_from_photo(path: str | os.PathLike = REST_PHOTO,
                        params: RatioDetector = RatioDetector()) -> np.ndarray:
    """Detect the 127 markers of a rest photo and return them in base-graph order, (127, 2) px."""
    points = require_full_set(detect_file(path, params), path)
    return points[base_graph_order(points)]


@functools.lru_cache(maxsize=4)
def _cached_template(path: str) -> np.ndarray:
    template = template_from_photo(path)
    template.setflags(write=False)
    return template


def rest_template(path: str | os.PathLike | None = None) -> np.ndarray:
    """(127, 2) float64 rest marker positions in base-graph order, from the shipped rest photo.

    Ring-6 corners come out at about (1199, 300), (1366, 576), (1211, 858), (888, 868), (720, 592),
    (874, 301) and the centre at about (1039, 582), as in SPEC §5.2.
    """
    return _cached_template(str(Path(path or REST_PHOTO).resolve())).copy()


def ring6_corners(template: np.ndarray) -> np.ndarray:
    """The six corners of the outer ring (its six points farthest from marker 0), by bearing: (6, 2).

    On the rest template they sit at bearings of about 29, 89, ..., 329 deg.
    """
    tpl = np.asarray(template, dtype=np.float64)
    outer = tpl[ring_slice(N_RINGS)]  # already sorted by bearing
    far = np.sort(np.argsort(np.linalg.norm(outer - tpl[0], axis=1))[-6:])
    return outer[far]
