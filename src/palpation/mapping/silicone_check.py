"""How well the reconstructed Silicone poses are checked: video truth against the phantom photo.

Two independent truths exist for the Silicone map: the video truth (label-1 markers, lifted with our
poses) and the photo truth (the VGG polygons of the phantom photo, stretched over the workspace). If the
poses were wrong by a path spacing or a sweep direction, the two would not overlap. We report
* IoU of video truth and photo truth on the 100 x 180 grid (SPEC §12 gives 0.2934 for the reference),
* the mean / median distance (mm) from each video-truth pixel and from each lifted annotation dot to the
  nearest photo-polygon pixel,
and, as a sensitivity check, the IoU when one layout parameter is moved, to show where the photo puts
its optimum compared with the priors.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import ndimage

from palpation.mapping.grid import silicone_grid
from palpation.mapping.lift import PLANE_MM, lift_to_camera, rasterise, silicone_to_world
from palpation.mapping.photo import PHOTO_SIZE, block_majority, photo_mask, read_polygons, swept_region
from palpation.mapping.silicone_poses import SweepLayout, silicone_poses


def silicone_truth_maps(markers: np.ndarray, labels: np.ndarray, layout: SweepLayout,
                        frames: np.ndarray | None = None):
    """Video truth and visited on the Silicone grid from (10, 16, 127, 2) markers and labels; `frames`
    picks which video frames count (default: the L = 5 central frames 2..13)."""
    frames = np.arange(2, 14) if frames is None else np.asarray(frames)
    poses = silicone_poses(layout, len(markers), markers.shape[1])[:, frames].reshape(-1, 2)
    px = markers[:, frames].reshape(-1, markers.shape[2], 2)
    lab = labels[:, frames].reshape(-1, markers.shape[2])
    world = silicone_to_world(lift_to_camera(px, PLANE_MM["silicone"]), poses)
    maps = rasterise(silicone_grid(), world, np.zeros(lab.shape), lab, np.zeros(len(px), np.int64), 1)
    return maps.truth[0], maps.visited[0], maps.dropped


def _distance_mm(points_rc: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Distance (grid px = mm) from (n, 2) row/col points to the nearest True pixel of `target`."""
    edt = ndimage.distance_transform_edt(~target)
    r = np.clip(np.round(points_rc[:, 0]).astype(int), 0, target.shape[0] - 1)
    c = np.clip(np.round(points_rc[:, 1]).astype(int), 0, target.shape[1] - 1)
    return edt[r, c]


def dot_world(dots: np.ndarray, counts: np.ndarray, layout: SweepLayout) -> np.ndarray:
    """Annotation dots (10, 16, 4, 2) sensor px lifted to world (n, 2) mm with the poses."""
    poses = silicone_poses(layout, len(dots), dots.shape[1])
    pts = []
    for v in range(len(dots)):
        for f in range(dots.shape[1]):
            if counts[v, f]:
                cam = lift_to_camera(dots[v, f, :counts[v, f]], PLANE_MM["silicone"])
                pts.append(silicone_to_world(cam[None], poses[v, f][None])[0])
    return np.concatenate(pts) if pts else np.zeros((0, 2))


def pose_check(markers, labels, dots, counts, layout: SweepLayout = SweepLayout(), polygons=None,
               size=PHOTO_SIZE, frames=None) -> dict:
    """Video truth vs photo truth under `layout`: IoU, distances, dot distances."""
    polygons = read_polygons() if polygons is None else polygons
    grid = silicone_grid()
    truth, visited, dropped = silicone_truth_maps(np.asarray(markers), np.asarray(labels), layout, frames)
    photo_full = block_majority(photo_mask(polygons, size), grid.shape)
    photo = photo_full & swept_region(visited)
    inter, union = int((truth & photo).sum()), int((truth | photo).sum())
    d_truth = _distance_mm(np.argwhere(truth).astype(float), photo_full)
    world = dot_world(np.asarray(dots), np.asarray(counts), layout)
    rr, cc, inside = grid.indices(world)
    d_dots = _distance_mm(np.stack([rr, cc], 1)[inside].astype(float), photo_full)
    return {
        "iou_video_photo": inter / union if union else float("nan"),
        "video_truth_px": int(truth.sum()), "photo_truth_px": int(photo.sum()), "intersection_px": inter,
        "video_truth_to_photo_mm": {"mean": float(d_truth.mean()), "median": float(np.median(d_truth)),
                                    "p90": float(np.percentile(d_truth, 90))},
        "dots_to_photo_mm": {"mean": float(d_dots.mean()), "median": float(np.median(d_dots)),
                             "p90": float(np.percentile(d_dots, 90)), "n": int(inside.sum()),
                             "outside_grid": int((~inside).sum())},
        "samples_outside_grid": int(dropped),
        "layout": dataclasses.asdict(layout),
    }


def sensitivity(markers, labels, dots, counts, layout: SweepLayout = SweepLayout(), polygons=None,
                size=PHOTO_SIZE, spans: dict | None = None) -> dict:
    """IoU and mean dot distance as one layout field moves over its span (others at `layout`)."""
    spans = spans or {"centre_x_mm": np.arange(-12, 13, 3.0), "centre_y_mm": np.arange(-12, 13, 3.0),
                      "path_spacing_mm": np.arange(-6, 7, 1.5), "mirror_sum": np.arange(-1.0, 1.01, 0.25)}
    polygons = read_polygons() if polygons is None else polygons
    out = {}
    for name, deltas in spans.items():
        rows = []
        for d in deltas:
            lay = dataclasses.replace(layout, **{name: getattr(layout, name) + float(d)})
            c = pose_check(markers, labels, dots, counts, lay, polygons, size)
            rows.append({"value": getattr(lay, name), "iou": c["iou_video_photo"],
                         "dots_mean_mm": c["dots_to_photo_mm"]["mean"]})
        best = max(rows, key=lambda r: r["iou"])
        out[name] = {"rows": rows, "best_value": best["value"], "best_iou": best["iou"]}
    return out
