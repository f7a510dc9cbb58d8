"""The real Silicone test set rebuilt from the annotation video (SPEC §13.4).

160 states = 10 videos x 16 frames. In each state we segment the clicked vessel dots, detect the dark
markers with the dots masked, track the 127 markers per video from the rest template, and label
them with the fixed chord rule. A dot (r ~9 video px) can hide a marker; such markers are
re-detected by registering the marker's own appearance from a frame where it is clear, using only
the pixels the dot leaves visible (`masked_fit`), or, if too little of the marker shows, filled from
its neighbours' motion and flagged not found.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

import cv2
import numpy as np

from palpation.camera import VIDEO_SCALE, sensor_to_video_px, video_to_sensor_px
from palpation.markers.detect import RatioDetector, ratio_candidates
from palpation.markers.order import similarity_prealign
from palpation.markers.template import rest_template
from palpation.markers.track import track_sequence
from palpation.paths import VIDEOS
from palpation.progress import bar
from palpation.realdata.video import read_states

VIDEO = VIDEOS / "dataset_annotations_silicone.mp4"
N_VIDEOS, N_FRAMES, N_MARKERS = 10, 16, 127
IMAGE_BOX = (21, 2, 1258, 698)  # x0, y0, x1, y1 (exclusive) of the sensor image in the video
# Per-frame work runs in this crop: the marker circle (691, 378) r 245 plus the 20 px half-width of
# the median blur, so results inside the circle equal the full frame's at a third of the pixels.
ROI_BOX = (426, 113, 956, 643)
LINE_ANGLE_DEG = (0.0, 0.0, 0.0, 0.0, -5.0, -5.0, -5.0, -5.0, 0.0, 0.0)  # per video, SPEC §13.4
# Label rule constants [fixed, SPEC §13.4]: kept apart from the camera model, which may be revised.
LABEL_CENTRE_PX, LABEL_CIRCLE_PX, LABEL_RADIUS_PX = (1040.0, 584.0), 380.0, 30.0
# Sweep of each video, `metadata_<path>_<direction>` as the viewer's Metadata panel names trials 1-10
# (predictions_sim_to_silicone.mp4, read by eye once); path 4 (videos 9-10) crosses no vessel.
SWEEP_NAMES = tuple(f"metadata_{path:.1f}_{direction:.1f}" for path in range(5) for direction in range(2))
DOT_COLOURS = ("red", "green", "blue", "magenta")  # click order
_DOT_HUES = np.array([0.0, 60.0, 120.0, 150.0])  # OpenCV hue (0..180) of each click colour

SOURCE_FILLED, SOURCE_BLOB, SOURCE_MASKED_FIT = 0, 1, 2


@dataclass(frozen=True)
class SiliconeParams:
    """Detection and tracking settings, lengths in annotation-video px unless named _orig_px."""

    dot_sat_min: int = 150  # dots are saturated colour on a grey image: HSV S > 150 and V > 150
    dot_val_min: int = 150
    dot_area_min_px2: int = 60  # drops compression specks (a dot interior is ~210 px2)
    dot_mask_px: float = 12.0  # masked before blob detection (SPEC)
    dot_cover_px: float = 10.5  # drawn dot incl. its 1 px black rim (r ~9.5): hidden from the fit
    near_dot_px: float = 20.0  # blobs this close to a dot may be clipped: re-fit them instead
    marker_area_max_px2: float = 400.0
    # > 255 turns the detector's glint repair off: the published Silicone set (built before it) stays
    # bit-identical; 250 would move 10 of its 20,320 marker positions by <= 0.17 px
    glint_min: float = 256.0
    max_step_orig_px: float = 15.0  # temporal gate: 3x the p99 step, < the rim-glare offset
    patch_half_px: int = 12
    search_px: int = 7  # masked-fit search radius around the tracked prediction
    prior_weight: float = 0.002  # weak pull to the prediction when the visible part is ambiguous
    visible_min: float = 0.15  # fraction of the marker core that must be visible to count as detected


# ----------------------------------------------------------------------------- states and dots
def state_index(video: int, frame: int) -> int:
    """1-based video (1..10) and frame (1..16) -> state 0..159."""
    if not (1 <= video <= N_VIDEOS and 1 <= frame <= N_FRAMES):
        raise ValueError(f"video must be 1..{N_VIDEOS} and frame 1..{N_FRAMES}, got {video}, {frame}")
    return N_FRAMES * (video - 1) + frame - 1


def segment_dots(frame_bgr: np.ndarray, p: SiliconeParams = SiliconeParams()
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Annotation dots of one frame: centres (n, 2) video px and colour index (n,) into DOT_COLOURS."""
    x0, y0, x1, y1 = IMAGE_BOX
    hsv = cv2.cvtColor(np.ascontiguousarray(frame_bgr[y0:y1, x0:x1]), cv2.COLOR_BGR2HSV)
    mask = ((hsv[..., 1] > p.dot_sat_min) & (hsv[..., 2] > p.dot_val_min)).astype(np.uint8)
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    keep = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= p.dot_area_min_px2) + 1
    hue = hsv[..., 0].astype(float)
    colours = []
    for k in keep:  # circular mean hue: red straddles 0/180
        ang = np.radians(2.0 * hue[labels == k])
        mean = np.degrees(np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())) / 2.0
        diff = np.abs((mean - _DOT_HUES + 90.0) % 180.0 - 90.0)
        colours.append(int(np.argmin(diff)))
    centres = centroids[keep] + np.array([x0, y0], float)
    return centres.reshape(-1, 2), np.asarray(colours, dtype=np.int8)


def _disc_mask(shape, centres: np.ndarray, radius: float) -> np.ndarray:
    mask = np.zeros(shape[:2], np.uint8)
    for c in np.asarray(centres).reshape(-1, 2):  # sub-pixel centre and radius (4 fractional bits)
        cv2.circle(mask, (int(round(16 * c[0])), int(round(16 * c[1]))), int(round(16 * radius)), 1, -1,
                   shift=4)
    return mask.astype(bool)


# ----------------------------------------------------------------------------- markers per frame
def video_detector(p: SiliconeParams = SiliconeParams(), origin=(0.0, 0.0)) -> RatioDetector:
    """The flat-tip ratio detector scaled to the annotation video (circle (691, 378) r 245), for an
    image whose top-left pixel sits at video px `origin`."""
    offset = (IMAGE_BOX[0] - float(origin[0]), IMAGE_BOX[1] - float(origin[1]))
    base = RatioDetector().scaled(VIDEO_SCALE, offset)
    return dataclasses.replace(base, area_max_px2=p.marker_area_max_px2, prune=False, glint_min=p.glint_min)


@dataclass(frozen=True)
class FrameViews:
    """One frame cropped to ROI_BOX: gray with dots painted as background, its background ratio,
    the mask of pixels no dot covers, and the crop's origin in video px."""

    gray: np.ndarray
    ratio: np.ndarray
    visible: np.ndarray
    origin: np.ndarray


def masked_views(frame_bgr: np.ndarray, dots: np.ndarray, p: SiliconeParams = SiliconeParams()
                 ) -> FrameViews:
    """Crop a video frame to the marker circle and prepare it for detection and masked fits."""
    x0, y0, x1, y1 = ROI_BOX
    origin = np.array([x0, y0], float)
    local = np.asarray(dots, float).reshape(-1, 2) - origin
    k = video_detector(p).background_px
    gray = cv2.cvtColor(np.ascontiguousarray(frame_bgr[y0:y1, x0:x1]), cv2.COLOR_BGR2GRAY)
    hidden = _disc_mask(gray.shape, local, p.dot_mask_px)
    gray[hidden] = cv2.medianBlur(gray, k)[hidden]  # a dot is not a dark marker
    background = cv2.medianBlur(gray, k).astype(np.float32)
    ratio = gray.astype(np.float32) / np.maximum(background, 1.0)
    visible = (~_disc_mask(gray.shape, local, p.dot_cover_px)).astype(np.float32)
    return FrameViews(gray, ratio, visible, origin)


def clear_detections(views: FrameViews, dots: np.ndarray, p: SiliconeParams = SiliconeParams()
                     ) -> np.ndarray:
    """Marker centroids (N, 2) video px whose blob no dot can clip (extras such as rim glare kept)."""
    pts = ratio_candidates(views.gray, video_detector(p, views.origin)) + views.origin
    if len(dots) and len(pts):
        near = np.linalg.norm(pts[:, None] - np.asarray(dots)[None], axis=-1).min(1) < p.near_dot_px
        pts = pts[~near]
    return pts


def _patch(image: np.ndarray, centre, half: int) -> np.ndarray:
    return cv2.getRectSubPix(image, (2 * half + 1, 2 * half + 1), (float(centre[0]), float(centre[1])))


def reference_patch(views: FrameViews, centre_px, p: SiliconeParams = SiliconeParams()) -> np.ndarray:
    """Ratio patch of a clearly visible marker centred at video px `centre_px`."""
    return _patch(views.ratio, np.asarray(centre_px, float) - views.origin, p.patch_half_px)


def masked_fit(views: FrameViews, reference: np.ndarray, prediction_px: np.ndarray,
               p: SiliconeParams = SiliconeParams()) -> tuple[np.ndarray, float]:
    """Register a marker's `reference` ratio patch near `prediction_px` using visible pixels only.

    Returns the centre (2,) video px and the visible fraction of the marker's dark core there.
    Integer search over +-search_px, then a 0.2 px grid; the weak prior decides only when the
    visible pixels cannot (marker almost fully covered).
    """
    half = p.patch_half_px
    core = reference < 0.85
    pred = np.asarray(prediction_px, float) - views.origin

    def cost(c):
        vis = _patch(views.visible, c, half) > 0.5
        if vis.sum() < 20:
            return np.inf
        return float(((_patch(views.ratio, c, half) - reference)[vis] ** 2).mean()
                     + p.prior_weight * ((c - pred) ** 2).sum())

    grid = np.arange(-p.search_px, p.search_px + 1, dtype=float)
    best = min([pred + np.array([dx, dy]) for dy in grid for dx in grid], key=cost)
    fine = np.arange(-1.0, 1.01, 0.2)
    best = min([best + np.array([dx, dy]) for dy in fine for dx in fine], key=cost)
    vis = _patch(views.visible, best, half) > 0.5
    return best + views.origin, float((core & vis).sum() / max(core.sum(), 1))


# ----------------------------------------------------------------------------- one video
def track_video(frames: np.ndarray, template: np.ndarray, p: SiliconeParams = SiliconeParams()
                ) -> dict[str, np.ndarray]:
    """Markers of one video's frames (T, H, W, 3): positions (T, 127, 2) sensor px and provenance."""
    dots, colours, views, dets = [], [], [], []
    for frame in frames:
        d, c = segment_dots(frame, p)
        views.append(masked_views(frame, d, p))
        dots.append(d), colours.append(c)
        dets.append(video_to_sensor_px(clear_detections(views[-1], d, p)))
    scale = np.sqrt(abs(np.linalg.det(similarity_prealign(template, dets[0])[:, :2])))
    positions, found = track_sequence(dets, template, p.max_step_orig_px)
    source = np.where(found, SOURCE_BLOB, SOURCE_FILLED).astype(np.int8)
    video_xy = sensor_to_video_px(positions)
    for t in range(len(frames)):
        for i in np.flatnonzero(~found[t]):  # missing markers lie under dots: fit what is visible
            clear = [u for u in np.argsort(np.abs(np.arange(len(frames)) - t)) if found[u, i]]
            if not clear:
                continue
            reference = reference_patch(views[clear[0]], video_xy[clear[0], i], p)
            centre, frac = masked_fit(views[t], reference, video_xy[t, i], p)
            if frac >= p.visible_min:
                positions[t, i] = video_to_sensor_px(centre)
                source[t, i] = SOURCE_MASKED_FIT
    return {"positions": positions, "found": source > SOURCE_FILLED, "source": source,
            "dots": [video_to_sensor_px(d) for d in dots], "colours": colours, "scale": scale}


# ----------------------------------------------------------------------------- labels
def chord_samples(dot_px: np.ndarray, angle_deg: float, n_samples: int = 50) -> np.ndarray | None:
    """Chord through a dot along the video's line angle, clipped to the image circle (SPEC §13.4).

    Returns (n_samples, 2) original px, or None if the chord's foot lies outside the circle.
    """
    centre, radius = np.asarray(LABEL_CENTRE_PX), LABEL_CIRCLE_PX
    a = np.radians(angle_deg)
    u = np.array([np.cos(a), np.sin(a)])
    p0 = np.asarray(dot_px, float)
    foot = p0 - np.dot(p0 - centre, u) * u
    dist = np.linalg.norm(foot - centre)
    if dist > radius:
        return None
    half = np.sqrt(radius ** 2 - dist ** 2)
    return foot + np.linspace(-half, half, n_samples)[:, None] * u


def chord_distance(markers_px: np.ndarray, dots_px: np.ndarray, angle_deg: float) -> np.ndarray:
    """(M,) distance of each marker to the nearest chord sample of the frame's dots (inf if none)."""
    markers = np.asarray(markers_px, float).reshape(-1, 2)
    dist = np.full(len(markers), np.inf)
    for dot in np.asarray(dots_px, float).reshape(-1, 2):
        chord = chord_samples(dot, angle_deg)
        if chord is not None:
            dist = np.minimum(dist, np.linalg.norm(markers[:, None] - chord[None], axis=-1).min(1))
    return dist


def label_markers(markers_px: np.ndarray, dots_px: np.ndarray, angle_deg: float,
                  radius_px: float = LABEL_RADIUS_PX) -> np.ndarray:
    """(M,) int8: 1 iff a marker lies < `radius_px` from a chord sample of any dot of the frame."""
    return (chord_distance(markers_px, dots_px, angle_deg) < radius_px).astype(np.int8)


# ----------------------------------------------------------------------------- the whole set
def build_silicone_set(path: str | os.PathLike = VIDEO, videos=range(1, N_VIDEOS + 1),
                       n_frames: int = N_FRAMES, p: SiliconeParams = SiliconeParams(),
                       template: np.ndarray | None = None, progress: bool = False,
                       workers: int = 1) -> dict[str, np.ndarray]:
    """Markers, provenance, dots and labels of the selected videos (1-based), first `n_frames` each.
    `progress`: a tqdm bar over the frames, advanced one video at a time (they are tracked per video).
    `workers` > 1 tracks the videos in that many processes (each video alone, so the same result)."""
    videos = list(videos)
    template = rest_template() if template is None else np.asarray(template, float)
    states = [state_index(v, f) for v in videos for f in range(1, n_frames + 1)]
    frames = read_states(path, states=states)
    if frames.shape[1:3] != (760, 1280):
        raise ValueError(f"{path}: frames are {frames.shape[2]}x{frames.shape[1]}, expected the "
                         "1280x760 annotation video (dataset_annotations_silicone.mp4)")
    nv, shape, max_dots = len(videos), (len(videos), n_frames), len(DOT_COLOURS)
    out = {"markers": np.zeros((*shape, N_MARKERS, 2), np.float32),
           "found": np.zeros((*shape, N_MARKERS), bool),
           "source": np.zeros((*shape, N_MARKERS), np.int8),
           "labels": np.zeros((*shape, N_MARKERS), np.int8),
           "chord_distance_px": np.full((*shape, N_MARKERS), np.inf, np.float32),
           "dots": np.full((*shape, max_dots, 2), np.nan, np.float32),
           "dot_colours": np.full((*shape, max_dots), -1, np.int8),
           "dot_counts": np.zeros(shape, np.int16),
           "similarity_scale": np.zeros(nv, np.float32),
           "line_angle_deg": np.array([LINE_ANGLE_DEG[v - 1] for v in videos], np.float32),
           "videos": np.array(videos, np.int16),
           "states": np.array(states, np.int16).reshape(shape),
           "frame_index": (5 * np.array(states, np.int32) + 4).reshape(shape)}
    frames_bar = bar(total=len(states), desc="silicone", unit="frame", enabled=progress)
    clips = [frames[k * n_frames:(k + 1) * n_frames] for k in range(nv)]
    for k, (v, res) in enumerate(zip(videos, _tracked(clips, template, p, workers))):
        frames_bar.update(n_frames)
        out["markers"][k], out["found"][k] = res["positions"], res["found"]
        out["source"][k], out["similarity_scale"][k] = res["source"], res["scale"]
        for t, (d, c) in enumerate(zip(res["dots"], res["colours"])):
            if len(d) > max_dots:
                raise ValueError(f"{path}: video {v} frame {t + 1} shows {len(d)} dots, at most "
                                 f"{max_dots} are possible; check the dot thresholds")
            out["dots"][k, t, :len(d)], out["dot_colours"][k, t, :len(c)] = d, c
            out["dot_counts"][k, t] = len(d)
            dist = chord_distance(res["positions"][t], d, LINE_ANGLE_DEG[v - 1])
            out["chord_distance_px"][k, t] = dist
            out["labels"][k, t] = (dist < LABEL_RADIUS_PX).astype(np.int8)
    frames_bar.close()
    return out


def _tracked(clips: list[np.ndarray], template: np.ndarray, p: SiliconeParams, workers: int):
    """track_video of each clip, in order; in `workers` spawned processes where > 1 (the tracking is Python-bound:
    threads gain ~10 %; 16 frames of one video pickle as ~47 MB)."""
    if workers <= 1 or len(clips) <= 1:
        yield from (track_video(c, template, p) for c in clips)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(min(workers, len(clips)), mp_context=multiprocessing.get_context("spawn")) as pool:
        yield from pool.map(track_video, clips, [template] * len(clips), [p] * len(clips))


def summarize(data: dict[str, np.ndarray], central_trim: int = 2) -> dict:
    """Counts and tracking statistics of a set from `build_silicone_set` (SPEC §13.4 numbers)."""
    src, labels = data["source"], data["labels"]
    steps = np.linalg.norm(np.diff(data["markers"].astype(np.float64), axis=1), axis=-1).ravel()
    central = labels[:, central_trim:labels.shape[1] - central_trim]
    colours = data["dot_colours"][data["dot_colours"] >= 0]
    return {
        "states": int(labels.shape[0] * labels.shape[1]),
        "markers_per_frame_min": int(np.isfinite(data["markers"][..., 0]).sum(-1).min()),
        "detected": int((src > SOURCE_FILLED).sum()), "detected_blob": int((src == SOURCE_BLOB).sum()),
        "detected_masked_fit": int((src == SOURCE_MASKED_FIT).sum()),
        "filled": int((src == SOURCE_FILLED).sum()),
        "frames_by_detected_count": {int(k): int(n) for k, n in
                                     zip(*np.unique(data["found"].sum(-1), return_counts=True))},
        "step_px": {"median": float(np.median(steps)), "p90": float(np.percentile(steps, 90)),
                    "p99": float(np.percentile(steps, 99)), "max": float(steps.max()),
                    "over_8px": int((steps > 8).sum()), "n": int(steps.size)},
        "dots": int(data["dot_counts"].sum()),
        "dots_by_colour": {DOT_COLOURS[c]: int((colours == c).sum()) for c in range(len(DOT_COLOURS))},
        "states_with_dots": int((data["dot_counts"] > 0).sum()),
        "positive_marker_frames": int(labels.sum()),
        "states_with_positives": int((labels.sum(-1) > 0).sum()),
        "positive_rate": float(labels.mean()),
        "central_positives": int(central.sum()), "central_nodes": int(central.size),
        "central_positive_rate": float(central.mean()) if central.size else None,
        "similarity_scale": [float(x) for x in data["similarity_scale"]],
    }
