"""Read the prediction-viewer videos (SPEC §13.5): per state, the coloured marker dots of a panel.

The viewer (1280x960, 10 fps) holds each state for 5 frames; frame 5s + 2 is the middle one, away
from the H.264 blur of a state change. Ground Truth and Hard Prediction draw label 1 magenta and
label 0 cyan on black, so one reader serves both; the other panels' crops were measured on a frame
(black panel interiors, identical in all three viewer videos).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

import cv2
import numpy as np

from palpation.progress import bar
from palpation.readers import open_video

FRAMES_PER_STATE = 5
STATE_FRAME_OFFSET = 2  # middle of the 5 identical frames
VIDEO_SIZE = (1280, 960)  # width, height

# (y0, y1, x0, x1) of each panel's black interior in viewer pixels.
PANEL_CROPS = {
    "ground_truth": (48, 452, 22, 426),
    "hard_prediction": (48, 452, 438, 841),
    "confusion": (48, 452, 853, 1257),
    "soft_prediction": (498, 902, 22, 426),
}

# A dot is ~7 px across (~35-50 px²); smaller blobs are compression speckle, larger ones merged dots.
MIN_DOT_AREA_PX = 8
MAX_DOT_AREA_PX = 120
LABEL_NONE, LABEL_NEG, LABEL_POS = -1, 0, 1


@dataclass(frozen=True)
class PanelDots:
    """Dots of one panel in one state: centroids in panel pixels (x right, y down) and labels 0/1."""

    xy: np.ndarray  # (N, 2) float64
    labels: np.ndarray  # (N,) int8


def state_frame(state: int) -> int:
    """Video frame index (0-based) to read for a state."""
    return FRAMES_PER_STATE * state + STATE_FRAME_OFFSET


def classify_colours(panel_bgr: np.ndarray) -> np.ndarray:
    """Per-pixel label: 1 magenta (R, B > 150, G < 100), 0 cyan (G, B > 150, R < 100), -1 otherwise."""
    img = np.asarray(panel_bgr).astype(np.int16)
    b, g, r = img[..., 0], img[..., 1], img[..., 2]
    out = np.full(img.shape[:2], LABEL_NONE, dtype=np.int8)
    out[(r > 150) & (b > 150) & (g < 100)] = LABEL_POS
    out[(g > 150) & (b > 150) & (r < 100)] = LABEL_NEG
    return out


def detect_dots(panel_bgr: np.ndarray, min_area_px: int = MIN_DOT_AREA_PX,
                max_area_px: int = MAX_DOT_AREA_PX) -> PanelDots:
    """Connected components of the coloured pixels; label = the majority colour of the component."""
    colour = classify_colours(panel_bgr)
    mask = (colour != LABEL_NONE).astype(np.uint8)
    n, comp, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    area = stats[1:, cv2.CC_STAT_AREA]
    keep = np.flatnonzero((area >= min_area_px) & (area <= max_area_px)) + 1
    # Count magenta pixels per component in one pass; the rest of the component is cyan.
    n_pos = np.bincount(comp[colour == LABEL_POS], minlength=n)
    labels = (2 * n_pos[keep] > stats[keep, cv2.CC_STAT_AREA]).astype(np.int8)
    return PanelDots(xy=centroids[keep].astype(np.float64), labels=labels)


def crop_panel(frame_bgr: np.ndarray, crop: str | tuple[int, int, int, int]) -> np.ndarray:
    """Cut a panel out of a viewer frame; `crop` is a PANEL_CROPS name or (y0, y1, x0, x1)."""
    y0, y1, x0, x1 = PANEL_CROPS[crop] if isinstance(crop, str) else crop
    return frame_bgr[y0:y1, x0:x1]


def read_panel(frame_bgr: np.ndarray, crop: str | tuple[int, int, int, int]) -> PanelDots:
    """Dots of one panel of a viewer frame."""
    return detect_dots(crop_panel(frame_bgr, crop))


def count_states(path: str | os.PathLike) -> int:
    """Number of states in a viewer video (frame count / 5)."""
    cap = _open(path)
    try:
        return int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) // FRAMES_PER_STATE
    finally:
        cap.release()


def iter_state_frames(path: str | os.PathLike,
                      states: Iterable[int] | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """Yield (state, BGR frame) in increasing state order; all states when `states` is None.

    Frames are decoded sequentially (grab without retrieve for skipped ones); a long gap is jumped
    with a seek, which OpenCV's FFmpeg backend resolves exactly by decoding from the key frame.
    """
    path = Path(path)
    n_states = count_states(path)
    wanted = range(n_states) if states is None else sorted(set(int(s) for s in states))
    bad = [s for s in wanted if not 0 <= s < n_states]
    if bad:
        raise ValueError(f"{path}: states {bad[:5]} out of range; the video holds {n_states} states")
    cap = _open(path)
    try:
        pos = 0
        for s in wanted:
            target = state_frame(s)
            if target - pos > 50:
                cap.set(cv2.CAP_PROP_POS_FRAMES, target)
                pos = target
            while pos < target:
                if not cap.grab():
                    raise ValueError(f"{path}: video ends at frame {pos}, before state {s}")
                pos += 1
            ok, frame = cap.read()
            pos += 1
            if not ok:
                raise ValueError(f"{path}: cannot decode frame {target} (state {s})")
            yield s, frame
    finally:
        cap.release()


def read_states(path: str | os.PathLike, crops: Iterable[str | tuple[int, int, int, int]],
                states: Iterable[int] | None = None, progress: bool = False) -> dict[str, list[PanelDots]]:
    """Dots of each requested panel for each state: {crop name or str(tuple): [PanelDots per state]}.
    `progress`: a tqdm bar over the states' frames."""
    crops = list(crops)
    out: dict[str, list[PanelDots]] = {str(c): [] for c in crops}
    states = None if states is None else [int(s) for s in states]  # counted below, so not a one-shot iterator
    total = (count_states(path) if states is None else len(set(states))) if progress else None
    for _, frame in bar(iter_state_frames(path, states), total=total, desc="panels", unit="frame",
                        enabled=progress):
        for c in crops:
            out[str(c)].append(read_panel(frame, c))
    return out


def _open(path: str | os.PathLike) -> cv2.VideoCapture:
    return open_video(path, "the reference videos live in data/reference/videos/ (restore the file from there)",
                      "viewer video", VIDEO_SIZE)[0]
