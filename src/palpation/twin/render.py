"""Render simulated trajectories: a figure of rest vs deformed markers, and one short MP4 each.

Reads only the simulate stage's outputs (trajectory npz files listed in manifests). The figure shows
each trajectory at its frame of largest mean marker displacement from rest (the deepest contact),
with displacements magnified; the videos show every recorded frame (slides every 2nd) with the
projected vessel centreline while in contact and the positive markers of the 30 px label rule.

Run it through the Hydra app `python -m palpation.apps.render_twin` (rule render_twin).
"""

from __future__ import annotations

import logging
from pathlib import Path

import cv2

from palpation.figures.twin_render import draw_frame, markers_figure
from palpation.io import atomic_path
from palpation.twin.output import load_trajectory, read_sim_manifest

log = logging.getLogger(__name__)
FPS = 30


def write_video(traj: dict, path: Path, name: str) -> Path:
    step = 2 if len(traj["markers"]) > 200 else 1  # keep slides to ~5 s
    frames = [draw_frame(traj, f, name) for f in range(0, len(traj["markers"]), step)]
    h, w = frames[0].shape[:2]
    with atomic_path(path, suffix=".mp4") as tmp:
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), FPS, (w, h))
        if not writer.isOpened():
            raise ValueError(f"OpenCV cannot open an mp4v writer for {path}; check the OpenCV build")
        for img in frames:
            writer.write(img)
        writer.release()
    return path


def trajectory_files(manifests: list[Path]) -> list[Path]:
    return [f for m in manifests for f in read_sim_manifest(m, "run the simulate stage first", allow_empty=True)[1]]


def render(manifests: list[Path], out_dir: Path) -> list[Path]:
    """Figure `markers.png/.pdf` of all trajectories and one `<name>.mp4` each, under `out_dir`."""
    files = trajectory_files(manifests)
    if not files:
        raise ValueError(f"no trajectory files listed in {[str(m) for m in manifests]}")
    outputs, panels = [], []
    for path in files:
        traj = load_trajectory(path)
        name = f"{path.parent.name}/{path.stem}"
        panels.append((name, traj))
        outputs.append(write_video(traj, out_dir / f"{path.parent.name}_{path.stem}.mp4", name))
        log.info("rendered %s (%d frames)", name, len(traj["markers"]))
    return outputs + markers_figure(panels, out_dir / "markers")
