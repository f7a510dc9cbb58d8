"""Detect and order a folder of flat-tip photos into a measured set, with per-photo statistics.

The markers are put into the template's base-graph order by the pre-aligned Hungarian, and
displacements are taken against the rest photo (press depth 0, SPEC §6.1/§17). A photo may miss up to
`max_missing` markers (painted over, out of focus): those are filled from the warped template plus
their found neighbours' displacement and flagged False in `found`, never given a neighbour's label.
The statistics are the ones SPEC §13.2 and §15.8 quote, so the two can be compared. Photos come with
their states from the paper's file names or from a manifest (`markers.manifest`).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from palpation.markers.detect import BlobDetector, RatioDetector, check_covers_circle, detect_markers, load_gray
from palpation.markers.lattice import N_MARKERS, base_graph_order, median_spacing_px, neighbours
from palpation.markers.manifest import PhotoInfo, paper_names, state_name
from palpation.markers.order import order_to_template, warp_template
from palpation.markers.template import require_full_set
from palpation.measured import MeasuredSet, MeasuredState, make_measured_set, parse_photo_name

log = logging.getLogger(__name__)
IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png"}
_TRAJECTORY_RANK = {"rest": 0, "press": 1, "twist_z": 2, "twist_x": 3, "slide": 4}


def list_photos(directory: str | os.PathLike) -> list[Path]:
    """The photos of a folder in a stable order: rest states, press, twist_z, twist_x, slide."""
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"{directory}: photo folder does not exist; set photos_dir")
    photos = [p for p in directory.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES]
    if not photos:
        raise FileNotFoundError(f"{directory}: no .jpg/.png photos found")
    key = lambda p: (_TRAJECTORY_RANK[parse_photo_name(p)["trajectory"]],  # noqa: E731
                     p.name.startswith("sensor_default_state"), p.name)
    return sorted(photos, key=key)


def order_photo(path: Path, template: np.ndarray, params: RatioDetector, max_missing: int = 0
                ) -> tuple[np.ndarray, np.ndarray, int]:
    """127 markers of one photo in template order, found mask (False = filled), raw candidate count."""
    gray = load_gray(path)
    check_covers_circle(gray, params, path)
    raw = detect_markers(gray, RatioDetector(**{**params.__dict__, "prune": False}))
    points = detect_markers(gray, params, reference=template)
    if not N_MARKERS - max_missing <= len(points) <= N_MARKERS:
        require_full_set(points, path)  # raises, naming the photo
    ordered, found = order_to_template(points, template)
    if not found.all():
        from palpation.markers.track import fill_missing

        predicted = warp_template(template, points)
        ordered = fill_missing(predicted, ordered, found, neighbours(predicted))
        log.warning("%s: markers %s not detected, filled from their neighbours (found=False)",
                    path.name, np.flatnonzero(~found).tolist())
    return ordered, found, len(raw)


def measure_photos(photos: list, template: np.ndarray, rest_photo: str,
                   params: RatioDetector = RatioDetector(), blob_counts: bool = True, max_missing: int = 0
                   ) -> tuple[MeasuredSet, list[dict[str, Any]]]:
    """Measured set of `photos` (displacement vs the photo named `rest_photo`) and per-photo stats.

    `photos`: paths with the paper's names, or `manifest.PhotoInfo` from a manifest.
    """
    infos = [p if isinstance(p, PhotoInfo) else paper_names([Path(p)])[0] for p in photos]
    names = [i.path.name for i in infos]
    if rest_photo not in names:
        raise ValueError(f"rest_photo '{rest_photo}' is not among the photos {names}")
    ordered, found, raw_counts = zip(*(order_photo(i.path, template, params, max_missing) for i in infos))
    markers, found = np.stack(ordered), np.stack(found)
    rest = markers[names.index(rest_photo)]
    states = [MeasuredState(name=i.name, source_file=i.path.name, trajectory=i.trajectory,
                            depth_mm=i.depth_mm, angle_deg=i.angle_deg) for i in infos]
    mset = make_measured_set(markers, found, rest, states, rest_source=rest_photo)
    rows = []
    for info, state, m, ok, n_raw in zip(infos, states, markers, found, raw_counts):
        p = info.path
        disp = np.linalg.norm(m - rest, axis=1)
        row = {"name": state.name, "source_file": p.name, "trajectory": state.trajectory,
               "n_candidates": n_raw, "n_markers": int(ok.sum()), "n_filled": int((~ok).sum()),
               "median_nn_spacing_px": median_spacing_px(m),
               "disp_median_px": float(np.median(disp)), "disp_max_px": float(disp.max()),
               # undeformed-sensor baselines (SPEC §15.8): mean marker error of a model that predicts
               # no deformation, from the rest template or from the press d=0 photo
               "baseline_mae_template_px": float(np.linalg.norm(m - template, axis=1).mean()),
               "baseline_mae_rest_photo_px": float(disp.mean())}
        if blob_counts:
            gray = load_gray(p)
            row["n_blob_default"] = len(detect_markers(gray, BlobDetector("default")))
            row["n_blob_meat_first_run"] = len(detect_markers(gray, BlobDetector("meat-first-run")))
        rows.append(row)
    return mset, rows


# The reference implementation's hand-placed markers (SPEC §5.2, §6.1), used only to replicate its
# numbers as a check of the ordering; the measured set itself never uses them.
REFERENCE_HAND_MARKERS = {
    "sensor_default_state": [(872, 300), (1364, 577), (718, 592)],
    "twist_x": [(762, 482), (845, 433), (1012, 430), (1067, 430), (1122, 430), (1197, 299)],
}


def reference_pipeline_baselines(photos: list[Path], rest_photo: str) -> dict[str, dict[str, float]]:
    """Undeformed baselines (SPEC §15.8) with the reference's pipeline: blob detectors + hand markers.

    Template: meat-first-run on sensor_default_state plus 3 hand markers; targets: default mode, plus
    6 hand markers on twist_x. Returns {state name: {baseline_mae_template_px, ..._rest_photo_px}}.
    """
    def detect(path: Path, mode: str) -> np.ndarray:
        points = detect_markers(load_gray(path), BlobDetector(mode))
        extra = next((v for k, v in REFERENCE_HAND_MARKERS.items() if path.name.startswith(k)), [])
        return require_full_set(np.vstack([points, np.reshape(extra, (-1, 2))]), path)

    template_photo = next(p for p in photos if p.name.startswith("sensor_default_state"))
    template = detect(template_photo, "meat-first-run")
    template = template[base_graph_order(template)]
    ordered = {p.name: order_to_template(detect(p, "default"), template)[0] for p in photos
               if p != template_photo}
    rest = ordered[rest_photo]
    return {state_name(Path(name)): {
        "baseline_mae_template_px": float(np.linalg.norm(m - template, axis=1).mean()),
        "baseline_mae_rest_photo_px": float(np.linalg.norm(m - rest, axis=1).mean())}
        for name, m in ordered.items() if name != rest_photo}
