"""The Silicone set as measured sequences (palpation.measured_sequences): markers, poses and vessels.

* markers, found, labels: the tracked Silicone set (realdata.silicone, 10 trials x 16 frames);
* poses: the reconstructed robot x, y of every frame (mapping.silicone_poses; the data carry none);
  the press depth is not recorded either, so every frame takes `depth_mm` (an assumption, in the json);
* vessels: the phantom photo's four `vein` polygons (mapping.photo) in the same world frame. The whole
  rectified photo spans the 180 x 100 mm workspace (SPEC §13.6) with the Silicone grid's axes
  (mapping.grid.silicone_grid: columns mirrored along x, rows along +y), so photo px (u, v) ->
  x = x_hi - u * 180 / W, y = y_lo + v * 100 / H. Each polygon becomes a centreline by binning its
  filled area along its principal axis (mean point per bin) and a diameter = area / length per bin.
"""

from __future__ import annotations

import numpy as np

from palpation.mapping.grid import silicone_grid
from palpation.mapping.photo import PHOTO_SIZE, photo_mask, read_polygons
from palpation.mapping.silicone_poses import SweepLayout, silicone_poses
from palpation.measured_sequences import SequenceSet, make_sequence_set

BIN_MM = 4.0  # centreline vertex spacing: a vessel bends over ~20 mm, the sensor footprint is ~39 mm
ASSUMED_DEPTH_MM = 3.0  # press depth of every frame: the twin's canonical slide depth (SPEC §4.1)


def photo_to_world(uv: np.ndarray, size: tuple[int, int] = PHOTO_SIZE) -> np.ndarray:
    """Photo px (u right, v down) -> world mm on the Silicone workspace (continuous grid rule)."""
    g = silicone_grid()
    uv = np.asarray(uv, np.float64)
    x = g.cols.hi - uv[..., 0] * g.cols.size / size[0]  # mirrored: photo left = +x
    y = g.rows.lo + uv[..., 1] * g.rows.size / size[1]
    return np.stack([x, y], axis=-1)


def centreline(mask_world_pts: np.ndarray, bin_mm: float = BIN_MM, px_area_mm2: float = 1.0
               ) -> tuple[np.ndarray, float]:
    """(k, 2) centreline and median diameter (mm) of one filled vessel given its pixels in world mm."""
    pts = np.asarray(mask_world_pts, np.float64)
    mean = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - mean, full_matrices=False)
    s = (pts - mean) @ vt[0]
    edges = np.arange(s.min(), s.max() + bin_mm, bin_mm)
    which = np.clip(np.digitize(s, edges) - 1, 0, len(edges) - 2)
    line, widths = [], []
    for b in range(len(edges) - 1):
        sel = which == b
        if sel.sum() < 3:
            continue
        line.append(pts[sel].mean(axis=0))
        length = min(edges[b + 1], s.max()) - max(edges[b], s.min())
        if length > 0.5 * bin_mm:  # partial end bins under-state the width
            widths.append(sel.sum() * px_area_mm2 / length)
    if len(line) < 2:
        raise ValueError("a vessel polygon is shorter than two centreline bins; check the VGG labels")
    return np.array(line), float(np.median(widths)) if widths else float("nan")


def phantom_vessels(polygons: list[np.ndarray] | None = None, size: tuple[int, int] = PHOTO_SIZE,
                    bin_mm: float = BIN_MM) -> tuple[list[np.ndarray], list[float]]:
    """Centrelines (world mm) and diameters (mm) of the photo's vessels, in label order."""
    polygons = read_polygons() if polygons is None else polygons
    g = silicone_grid()
    px_area = (g.cols.size / size[0]) * (g.rows.size / size[1])
    lines, diameters = [], []
    for poly in polygons:
        mask = photo_mask([poly], size)
        v, u = np.nonzero(mask)
        line, d = centreline(photo_to_world(np.stack([u, v], 1), size), bin_mm, px_area)
        lines.append(line)
        diameters.append(d)
    return lines, diameters


def silicone_sequences(data: dict[str, np.ndarray], rest_px: np.ndarray, layout: SweepLayout = SweepLayout(),
                       depth_mm: float = ASSUMED_DEPTH_MM, polygons: list[np.ndarray] | None = None,
                       source: str = "", bin_mm: float = BIN_MM) -> SequenceSet:
    """The SequenceSet of a Silicone set from realdata.silicone.build_silicone_set (any videos subset)."""
    videos = [int(v) for v in data["videos"]]
    n_frames = data["markers"].shape[1]
    poses_xy = silicone_poses(layout, n_frames=n_frames)[np.array(videos) - 1]
    pose = np.concatenate([poses_xy, np.full((*poses_xy.shape[:2], 1), float(depth_mm))], axis=-1)
    lines, diameters = phantom_vessels(polygons, bin_mm=bin_mm)
    trials = [{"name": f"silicone_{v:02d}", "video": v, "sweep": f"path {p} direction {d}"}
              for v, (p, d) in zip(videos, (_sweep(v) for v in videos))]
    return make_sequence_set(
        data["markers"], data["found"], rest_px, pose, lines, trials, diameters, labels=data["labels"],
        source=source, pose_source="reconstructed: palpation.mapping.silicone_poses (SPEC §13.6: no robot poses)",
        depth_source=f"assumed {depth_mm} mm for every frame (the Silicone data record no depth)",
        vessel_source="phantom photo VGG polygons (data/reference/phantom), centrelines by principal-axis bins",
        rest_source="rest template (sensor_default_state.png): the Silicone set has no rest frame",
        world_frame="robot x, y mm of the Silicone workspace x in [-425, -245], y in [-54, 46] (SPEC §12)",
        layout={k: getattr(layout, k) for k in layout.__dataclass_fields__})


def _sweep(video: int) -> tuple[int, int]:
    from palpation.mapping.silicone_poses import sweep_of

    return sweep_of(video - 1)
