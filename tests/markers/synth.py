"""Unseen test photos made from the shipped flat-tip photos, with known marker labels.

Each maker takes a grayscale photo and its (127, 2) labels in template order (the markers the
detector orders on the shipped photo) and returns a new photo and where those markers now are:
* `warp`: affine / perspective (a camera a little off-axis, a different mount scale or roll);
* `rim_press`: markers pushed outward near one point of the rim (a press near the edge);
* `glint`: a saturated specular ellipse over or beside a marker (its centre must not move);
* `paint_out`: a marker inpainted away (it must come out missing, not as a neighbour's label).
Only OpenCV and numpy; deterministic for given arguments.
"""

from __future__ import annotations

import functools
from pathlib import Path

import cv2
import numpy as np

from palpation.markers.detect import CIRCLE_CENTRE_PX, RatioDetector, load_gray
from palpation.markers.manifest import state_name
from palpation.markers.photoset import list_photos, order_photo
from palpation.markers.template import rest_template
from palpation.paths import FLAT_TIP_PHOTOS

# state name (press_d0, sensor_default_state, press_d4, twist_z_d4_a90, twist_x_d2_a20, slide_d3) -> file
PHOTOS = {state_name(p): p for p in list_photos(FLAT_TIP_PHOTOS)}


@functools.lru_cache(maxsize=8)
def _source(name: str) -> tuple[np.ndarray, np.ndarray]:
    path = Path(PHOTOS[name])
    labels, _, _ = order_photo(path, rest_template(), RatioDetector())
    gray = load_gray(path)
    gray.setflags(write=False)
    labels.setflags(write=False)
    return gray, labels


def source(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(gray photo, (127, 2) labels in template order) of a shipped photo, e.g. "twist_x_d2_a20"."""
    gray, labels = _source(name)
    return gray.copy(), labels.copy()


def similarity_matrix(angle_deg=0.0, scale=1.0, shift=(0.0, 0.0), shear=0.0, tilt=(0.0, 0.0),
                      centre=CIRCLE_CENTRE_PX) -> np.ndarray:
    """3x3 map about the circle centre: roll, scale, shear, shift and a perspective tilt (1/px)."""
    c = np.asarray(centre, float)
    a = np.radians(angle_deg)
    lin = scale * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) @ np.array([[1, shear], [0, 1]])
    to_c, back = np.eye(3), np.eye(3)
    to_c[:2, 2], back[:2, 2] = -c, c + np.asarray(shift, float)
    m = np.eye(3)
    m[:2, :2] = lin
    m[2, :2] = tilt
    return back @ m @ to_c


def warp(gray: np.ndarray, labels: np.ndarray, matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    h, w = gray.shape
    out = cv2.warpPerspective(gray, matrix, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    moved = cv2.perspectiveTransform(labels.reshape(-1, 1, 2).astype(np.float64), matrix).reshape(-1, 2)
    return out, moved


def rim_press(gray: np.ndarray, labels: np.ndarray, bearing_deg: float, amount_px: float,
              sigma_px: float = 110.0, rim_px: float = 330.0) -> tuple[np.ndarray, np.ndarray]:
    """Push the image outward (away from the circle centre) around the rim point at `bearing_deg`
    (clockwise from image-up); the push falls off as a Gaussian of width `sigma_px`."""
    c = np.asarray(CIRCLE_CENTRE_PX, float)
    b = np.radians(bearing_deg)
    peak = c + rim_px * np.array([np.sin(b), -np.cos(b)])

    def push(xy: np.ndarray) -> np.ndarray:
        r = xy - c
        unit = r / np.maximum(np.linalg.norm(r, axis=-1, keepdims=True), 1e-9)
        g = np.exp(-((xy - peak) ** 2).sum(-1) / (2 * sigma_px ** 2))
        return amount_px * g[..., None] * unit

    h, w = gray.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    maps = np.stack([xx, yy], -1)
    y0, y1 = max(int(c[1]) - 420, 0), min(int(c[1]) + 420, h)  # the push is ~0 outside the circle
    x0, x1 = max(int(c[0]) - 420, 0), min(int(c[0]) + 420, w)
    target = maps[y0:y1, x0:x1].astype(np.float64)
    src = target.copy()
    for _ in range(6):  # invert x + push(x) = target by fixed point (|d push / dx| << 1)
        src = target - push(src)
    maps[y0:y1, x0:x1] = src
    out = cv2.remap(gray, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out, labels + push(labels)


def glint(gray: np.ndarray, at: np.ndarray, axes=(9, 3), angle_deg: float = 30.0,
          offset=(0.0, 0.0)) -> np.ndarray:
    """A saturated specular ellipse (soft 1-px edge) centred at `at + offset`."""
    mask = np.zeros(gray.shape, np.uint8)
    centre = tuple(int(round(v)) for v in np.asarray(at, float) + offset)
    cv2.ellipse(mask, centre, tuple(int(a) for a in axes), angle_deg, 0, 360, 255, -1, cv2.LINE_AA)
    alpha = cv2.GaussianBlur(mask, (3, 3), 0).astype(np.float32) / 255.0
    return np.round(gray * (1 - alpha) + 255.0 * alpha).astype(np.uint8)


def paint_out(gray: np.ndarray, at: np.ndarray, radius_px: int = 16) -> np.ndarray:
    """Inpaint a marker away (the gel around it fills in)."""
    mask = np.zeros(gray.shape, np.uint8)
    cv2.circle(mask, tuple(int(round(v)) for v in at), radius_px, 255, -1)
    return cv2.inpaint(gray, mask, 5, cv2.INPAINT_TELEA)


def sweep(n_warps: int = 8, seed: int = 0) -> dict[str, list[bool]]:
    """Every shipped photo under `n_warps` random warps, 4 rim presses, 5 glints and 2 dropouts: per
    case, did the detector give every marker its right slot within 2 px (dropouts: exactly the painted
    slots missing)?"""
    from palpation.markers.detect import detect_markers
    from palpation.markers.order import order_to_template

    rng = np.random.default_rng(seed)
    tpl = rest_template()
    results: dict[str, list[bool]] = {"warp": [], "rim_press": [], "glint": [], "dropout": []}

    def ok(gray, labels, missing=()):
        ordered, found = order_to_template(detect_markers(gray), tpl)
        err = np.linalg.norm(ordered - labels, axis=1)
        return np.flatnonzero(~found).tolist() == list(missing) and err[found].max() <= 2.0

    for name in PHOTOS:
        gray, labels = source(name)
        for _ in range(n_warps):  # roll, scale, shift, shear, tilt within a fisheye mount's play
            m = similarity_matrix(rng.uniform(-8, 8), rng.uniform(0.93, 1.05), rng.uniform(-12, 12, 2),
                                  rng.uniform(-0.05, 0.05), rng.uniform(-1.5e-4, 1.5e-4, 2))
            results["warp"].append(ok(*warp(gray, labels, m)))
        for bearing in (0.0, 90.0, 200.0, 300.0):
            results["rim_press"].append(ok(*rim_press(gray, labels, bearing, rng.uniform(8, 18))))
        for marker in rng.choice(127, 5, replace=False):
            g = glint(gray, labels[marker], axes=(int(rng.integers(6, 13)), int(rng.integers(2, 5))),
                      angle_deg=rng.uniform(0, 180), offset=rng.uniform(-4, 4, 2))
            results["glint"].append(ok(g, labels))
        for k in (1, 3):
            painted = sorted(rng.choice(127, k, replace=False).tolist())
            g = gray
            for i in painted:
                g = paint_out(g, labels[i])
            results["dropout"].append(ok(g, labels, painted))
    return results


if __name__ == "__main__":  # python tests/markers/synth.py [n_warps]
    import sys

    res = sweep(int(sys.argv[1]) if len(sys.argv) > 1 else 8)
    for kind, passed in res.items():
        print(f"{kind:10s} {sum(passed)}/{len(passed)} photos: every marker in its slot within 2 px")
