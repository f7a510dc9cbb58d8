"""Reading held states from the reference mp4 videos with OpenCV.

The shipped videos show each state for `hold` identical frames (SPEC §13.4, §13.5). Frames at the
start of a hold can still carry H.264 residue of the previous state, so one frame per state is read
at a fixed `offset` inside its hold: 4 for the annotation video, 2 for the prediction videos.
"""

from __future__ import annotations

import os

import cv2
import numpy as np

from palpation.readers import open_video

ANNOTATION_OFFSET = 4  # SPEC §13.4: state s -> frame 5s + 4
PREDICTION_OFFSET = 2  # SPEC §13.5: state s -> frame 5s + 2


def _open(path: str | os.PathLike) -> tuple[cv2.VideoCapture, int]:
    return open_video(path, "restore the original file from data/reference/videos/ (the repository ships them)")


def frame_count(path: str | os.PathLike) -> int:
    """Number of frames OpenCV reports for the video at `path`."""
    cap, n_frames = _open(path)
    cap.release()
    return n_frames


def read_frames(path: str | os.PathLike, indices) -> np.ndarray:
    """Frames at 0-based `indices` as a (len(indices), H, W, 3) uint8 BGR array.

    Decodes sequentially up to the largest index (seeking in H.264 is not frame-exact everywhere).
    """
    idx = np.asarray(list(indices), dtype=np.int64)
    cap, n_frames = _open(path)
    try:
        bad = idx[(idx < 0) | (idx >= n_frames)]
        if bad.size:
            raise ValueError(f"frame index {int(bad[0])} is out of range for video {path} "
                             f"({n_frames} frames, valid 0..{n_frames - 1}); check the state indices")
        wanted = {int(i) for i in idx}
        found: dict[int, np.ndarray] = {}
        last = int(idx.max()) if idx.size else -1
        for i in range(last + 1):
            ok = cap.grab()
            if not ok:
                raise ValueError(f"video {path}: decoding stopped at frame {i} of {n_frames}; "
                                 "the file is truncated or corrupted, restore it")
            if i in wanted:
                ok, frame = cap.retrieve()
                if not ok:
                    raise ValueError(f"video {path}: frame {i} could not be decoded; restore the file")
                found[i] = frame
    finally:
        cap.release()
    if not idx.size:
        return np.zeros((0, 0, 0, 3), dtype=np.uint8)
    return np.stack([found[int(i)] for i in idx])


def state_frame_indices(states, hold: int = 5, offset: int = ANNOTATION_OFFSET) -> np.ndarray:
    """Video frame index read for each state: hold*s + offset."""
    if not 0 <= offset < hold:
        raise ValueError(f"offset {offset} must lie inside the hold of {hold} frames (0..{hold - 1})")
    return hold * np.asarray(list(states), dtype=np.int64) + offset


def n_states(path: str | os.PathLike, hold: int = 5) -> int:
    """Number of complete held states in the video."""
    return frame_count(path) // hold


def read_states(path: str | os.PathLike, hold: int = 5, offset: int = ANNOTATION_OFFSET,
                states=None) -> np.ndarray:
    """One frame per held state (all states if `states` is None): (S, H, W, 3) uint8 BGR."""
    if states is None:
        states = range(n_states(path, hold))
    return read_frames(path, state_frame_indices(states, hold, offset))
