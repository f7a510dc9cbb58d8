"""Dark-marker detection inside the fisheye image circle with OpenCV (SPEC §13.2).

Three detectors share one entry point, `detect_markers(image, params)`:
* `RatioDetector` (default): divide by a median-blur background, threshold the ratio, filter the
  connected components, take contrast-weighted centroids, then drop rim-glare false positives by a
  dummy-cost Hungarian match to a reference lattice. Finds all 127 markers on every flat-tip photo.
* `BlobDetector(mode="default")` / `BlobDetector(mode="meat-first-run")`: the reference's
  `SimpleBlobDetector` settings, kept for comparison (they miss markers: 121 on twist_x, 103 on
  sensor_default_state).
All lengths are in pixels of the image passed in; `RatioDetector.scaled` adapts them to a resized
image (the annotation video shows the sensor at 0.6443).
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

import cv2
import numpy as np

from palpation.markers.lattice import ideal_hex_lattice, median_spacing_px
from palpation.markers.order import match_with_dummy, warp_template
from palpation.readers import read_image

CIRCLE_CENTRE_PX = (1040.0, 584.0)
CIRCLE_RADIUS_PX = 380.0


@dataclass(frozen=True)
class RatioDetector:
    """Parameters of the ratio detector, in pixels of the analysed image."""

    background_px: int = 61  # median-blur kernel (odd), much larger than a marker
    ratio_max: float = 0.72  # a marker pixel is darker than 72% of its background
    background_min: float = 40.0  # ignore the dark vignette outside the lit dome
    opening_px: int = 3
    area_min_px2: float = 60.0
    area_max_px2: float = 1200.0
    aspect_max: float = 2.2  # bounding-box long/short side
    fill_min: float = 0.5  # component area / bounding-box area
    circle_centre_px: tuple[float, float] = CIRCLE_CENTRE_PX
    circle_radius_px: float = CIRCLE_RADIUS_PX
    prune: bool = True  # drop false positives against a reference lattice
    dummy_factor: float = 0.5  # dummy cost of that match, in spacings
    # A reference slot left empty may take a component that failed only the shape filters (a glint
    # inside a marker splits it into a crescent: twist_x marker near (762, 482) has fill 0.49).
    rescue: bool = True
    rescue_aspect_max: float = 3.0
    rescue_fill_min: float = 0.3
    # A specular glint (saturated, >= glint_min) across a marker splits it in two and drags the
    # centroid ~6 px. Glint pixels that a closing of glint_close_px bridges between dark pixels are
    # given back to the marker, with the mean weight of its dark pixels. Photos without saturated
    # pixels next to markers (all shipped ones) come out unchanged.
    glint_min: float = 250.0
    glint_close_px: int = 15

    def scaled(self, factor: float, offset_px: tuple[float, float] = (0.0, 0.0)) -> "RatioDetector":
        """The same detector for an image resized by `factor` then shifted by `offset_px`."""
        odd = lambda n: max(3, int(round(n)) | 1)  # noqa: E731  (kernels must be odd)
        return dataclasses.replace(
            self,
            background_px=odd(self.background_px * factor),
            opening_px=odd(self.opening_px * factor) if self.opening_px > 1 else 1,
            glint_close_px=odd(self.glint_close_px * factor),
            area_min_px2=self.area_min_px2 * factor ** 2,
            area_max_px2=self.area_max_px2 * factor ** 2,
            circle_centre_px=(self.circle_centre_px[0] * factor + offset_px[0],
                              self.circle_centre_px[1] * factor + offset_px[1]),
            circle_radius_px=self.circle_radius_px * factor,
        )


@dataclass(frozen=True)
class BlobDetector:
    """The reference's `SimpleBlobDetector` modes: "default" or "meat-first-run"."""

    mode: str = "default"
    circle_centre_px: tuple[float, float] = CIRCLE_CENTRE_PX
    circle_radius_px: float = CIRCLE_RADIUS_PX

    def opencv_params(self) -> cv2.SimpleBlobDetector_Params:
        p = cv2.SimpleBlobDetector_Params()
        p.filterByColor, p.blobColor = True, 0
        if self.mode == "default":
            p.minThreshold, p.maxThreshold = 0, 200
            p.filterByArea, p.minArea, p.maxArea = True, 120, 1000
        elif self.mode == "meat-first-run":
            p.minThreshold, p.maxThreshold, p.thresholdStep = 0, 150, 5
            p.minDistBetweenBlobs = 40
            p.filterByArea, p.minArea, p.maxArea = True, 300, 600
            p.filterByCircularity = p.filterByInertia = p.filterByConvexity = False
            p.minRepeatability = 4
        else:
            raise ValueError(f"unknown BlobDetector mode '{self.mode}': use 'default' or 'meat-first-run'")
        return p


def load_gray(path: str | os.PathLike) -> np.ndarray:
    """Read a photo as 8-bit grayscale (readers.read_image: FileNotFoundError if missing, ValueError if damaged)."""
    return read_image(path, "restore it or remove it from the photo folder", "photo")


def to_gray(image: np.ndarray) -> np.ndarray:
    """(H, W) or (H, W, 3) BGR uint8 -> (H, W) uint8."""
    image = np.asarray(image)
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(f"expected an 8-bit grayscale or BGR image, got shape {image.shape} {image.dtype}")
    return image


def _inside_circle(points: np.ndarray, centre, radius: float) -> np.ndarray:
    return np.linalg.norm(points - np.asarray(centre), axis=1) < radius


def check_covers_circle(gray: np.ndarray, p: RatioDetector, where: str | os.PathLike = "image") -> None:
    """A one-line error, instead of an OpenCV assertion, for an image that does not hold the sensor circle."""
    (cx, cy), r = p.circle_centre_px, p.circle_radius_px
    h, w = gray.shape[:2]
    if not (0 <= cx < w and 0 <= cy < h):  # a circle cut by the frame edge is fine, one off it is not
        raise ValueError(f"{where}: {w}x{h} px image does not hold the sensor circle (centre ({cx:g}, {cy:g}) px, "
                         f"radius {r:g} px); use the camera's full frames or set detector.circle_centre_px/"
                         "circle_radius_px for this camera")


def ratio_components(gray: np.ndarray, p: RatioDetector) -> tuple[np.ndarray, np.ndarray]:
    """Dark components that pass the area and rescue filters: centroids (K, 2) px, strict (K,) mask.

    `strict` marks those that also pass the SPEC shape filters (aspect, fill).
    """
    check_covers_circle(gray, p)
    # work on the circle's bounding box plus the blur radius: same result, ~3x fewer pixels
    cx, cy = p.circle_centre_px
    reach = p.circle_radius_px + p.background_px // 2 + 1
    x0, y0 = max(int(cx - reach), 0), max(int(cy - reach), 0)
    gray = gray[y0:int(cy + reach) + 1, x0:int(cx + reach) + 1]
    background = cv2.medianBlur(gray, p.background_px).astype(np.float32)
    ratio = gray.astype(np.float32) / np.maximum(background, 1.0)
    h, w = gray.shape
    yy, xx = np.mgrid[y0:y0 + h, x0:x0 + w]
    in_circle = (xx - cx) ** 2 + (yy - cy) ** 2 < p.circle_radius_px ** 2
    mask = ((ratio < p.ratio_max) & (background > p.background_min) & in_circle).astype(np.uint8)
    if p.opening_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((p.opening_px, p.opening_px), np.uint8))
    glint = _glint_fill(gray, mask, p)
    mask |= glint
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    _, _, bw, bh, area = stats[1:].T
    aspect = np.maximum(bw, bh) / np.maximum(np.minimum(bw, bh), 1)
    fill = area / (bw * bh)
    sized = (area >= p.area_min_px2) & (area <= p.area_max_px2)
    strict = sized & (aspect <= p.aspect_max) & (fill >= p.fill_min)
    relaxed = sized & (aspect <= p.rescue_aspect_max) & (fill >= p.rescue_fill_min)
    # contrast-weighted centroid: darker pixels (low ratio) count more, sub-pixel and glare-robust
    weight = np.clip(1.0 - ratio, 0.0, None).ravel()
    lab = labels.ravel()
    on = lab > 0
    if glint.any():  # a glint pixel weighs as much as the mean dark pixel of its marker
        added = glint.ravel().astype(bool)
        dark = on & ~added
        mean_dark = (np.bincount(lab[dark], weights=weight[dark], minlength=n)
                     / np.maximum(np.bincount(lab[dark], minlength=n), 1))
        weight = weight.copy()
        weight[added] = mean_dark[lab[added]]
    wsum = np.bincount(lab[on], weights=weight[on], minlength=n)
    wx = np.bincount(lab[on], weights=(weight * xx.ravel())[on], minlength=n)
    wy = np.bincount(lab[on], weights=(weight * yy.ravel())[on], minlength=n)
    idx = np.flatnonzero(relaxed) + 1
    centroids = np.stack([wx[idx] / wsum[idx], wy[idx] / wsum[idx]], axis=1)
    return centroids, strict[relaxed]


def _glint_fill(gray: np.ndarray, mask: np.ndarray, p: RatioDetector) -> np.ndarray:
    """uint8 mask of the glint pixels that lie inside a marker (bridged by a closing of its dark pixels)."""
    bright = (gray >= p.glint_min).astype(np.uint8)
    if not bright.any():
        return np.zeros_like(mask)
    bright = cv2.dilate(bright, np.ones((5, 5), np.uint8))  # the glint's soft rim is neither dark nor bright
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (p.glint_close_px, p.glint_close_px))
    closed = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, k)
    fill = closed & bright & (1 - mask)
    # A glint across a marker's edge bites a notch that no closing fills: fit a circle to the
    # marker's own edge (its boundary away from the glint) and give it the glint pixels inside.
    whole = mask | fill
    n, labels, stats, _ = cv2.connectedComponentsWithStats(whole, connectivity=8)
    touched = np.unique(labels[(bright > 0) & (labels > 0)])
    edge = whole & (1 - cv2.erode(whole, np.ones((3, 3), np.uint8))) & (1 - cv2.dilate(bright, np.ones((3, 3))))
    for i in touched[stats[touched, cv2.CC_STAT_AREA] <= p.area_max_px2]:
        ys, xs = np.nonzero((labels == i) & (edge > 0))
        if len(xs) < 8:
            continue
        # algebraic (Kasa) circle fit: x^2 + y^2 + D x + E y + F = 0
        D, E, F = np.linalg.lstsq(np.stack([xs, ys, np.ones_like(xs)], 1).astype(float),
                                  -(xs ** 2 + ys ** 2).astype(float), rcond=None)[0]
        cx, cy = -D / 2, -E / 2
        r = np.sqrt(max(cx * cx + cy * cy - F, 0.0))
        if not r < 0.5 * np.sqrt(p.area_max_px2):  # not a marker-sized disc: leave it to the filters
            continue
        disc = np.zeros_like(mask)
        cv2.circle(disc, (int(round(cx)), int(round(cy))), int(round(r)), 1, -1)
        fill |= disc & bright & (1 - mask)
    return fill


def ratio_candidates(gray: np.ndarray, p: RatioDetector) -> np.ndarray:
    """Centroids that pass the strict ratio/shape filters, before pruning: (N, 2) px."""
    centroids, strict = ratio_components(gray, p)
    return centroids[strict]


def blob_candidates(gray: np.ndarray, p: BlobDetector) -> np.ndarray:
    """Keypoints of the reference's SimpleBlobDetector inside the image circle: (N, 2) px."""
    keypoints = cv2.SimpleBlobDetector_create(p.opencv_params()).detect(gray)
    pts = np.array([k.pt for k in keypoints], dtype=np.float64).reshape(-1, 2)
    return pts[_inside_circle(pts, p.circle_centre_px, p.circle_radius_px)]


def detect_markers(image: np.ndarray, params: RatioDetector | BlobDetector = RatioDetector(),
                   reference: np.ndarray | None = None, rotation_deg: float = 0.0,
                   reference_is_aligned: bool = False) -> np.ndarray:
    """Unordered marker centres (N, 2) px in `image` (grayscale or BGR uint8).

    For the ratio detector with `prune`, candidates are matched to `reference` (a marker layout such
    as the rest template; default an ideal 127-marker hexagon, `rotation_deg` its roll guess) and
    those left to a dummy are dropped. The reference is first warped onto the candidates (~0.2 s);
    pass `reference_is_aligned=True` when it already sits in this image's pixels (e.g. the previous
    video frame's markers) to skip that. Blob modes return the raw keypoints, as in the reference.
    """
    gray = to_gray(image)
    if isinstance(params, BlobDetector):
        return blob_candidates(gray, params)
    centroids, strict = ratio_components(gray, params)
    pts = centroids[strict]
    if not params.prune or len(pts) < 3:
        return pts
    ref = ideal_hex_lattice() if reference is None else np.asarray(reference, float)
    target = ref if reference_is_aligned else warp_template(ref, pts, rotation_deg=rotation_deg)
    dummy_px = params.dummy_factor * median_spacing_px(target)
    slot = match_with_dummy(pts, target, dummy_px)
    kept = pts[slot >= 0]
    empty = np.setdiff1d(np.arange(len(ref)), slot)
    if params.rescue and len(empty):
        spare = centroids[~strict]
        rescued = match_with_dummy(spare, target[empty], dummy_px)
        kept = np.vstack([kept, spare[rescued >= 0]])
    return kept


def detect_file(path: str | os.PathLike, params: RatioDetector | BlobDetector = RatioDetector(),
                reference: np.ndarray | None = None) -> np.ndarray:
    """`detect_markers` on an image file."""
    return detect_markers(load_gray(path), params, reference)
