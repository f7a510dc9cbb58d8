"""The twin's renders: rest vs deformed markers at the deepest frame (figure) and one MP4 per trajectory.

Reads only the simulate stage's outputs (trajectory npz files listed in manifests). The figure shows
each trajectory at its frame of largest mean marker displacement from rest (the deepest contact),
with displacements magnified; the videos show every recorded frame (slides every 2nd) with the
projected vessel centreline while in contact and the positive markers of the 30 px label rule.

Run it through the Hydra app `python -m palpation.apps.render_twin` (rule render_twin).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from palpation.camera import DEFAULT_CAMERA, IMAGE_SIZE_PX  # noqa: E402
from palpation.io import atomic_path, save_figure  # noqa: E402
from palpation.twin.output import load_trajectory, read_sim_manifest  # noqa: E402

log = logging.getLogger(__name__)
FPS = 30
ARROW_GAIN = 3.0  # displacement magnification in the figure
VIDEO_SCALE = 0.5  # 1920x1080 -> 960x540


def deepest_frame(traj: dict) -> int:
    """Recorded frame with the largest mean marker displacement from the undeformed markers."""
    disp = np.linalg.norm(traj["markers"] - traj["rest_markers_px"][None], axis=-1).mean(axis=1)
    return int(np.argmax(disp))


def plot_markers(ax, traj: dict, title: str) -> None:
    """Rest (grey) vs deformed (red) markers at the deepest frame, arrows x ARROW_GAIN."""
    f = deepest_frame(traj)
    rest, now = traj["rest_markers_px"], traj["markers"][f]
    ax.add_patch(plt.Circle(DEFAULT_CAMERA.centre, DEFAULT_CAMERA.circle_radius_px, fill=False, color="0.7"))
    ax.scatter(*rest.T, s=12, facecolors="none", edgecolors="0.5", label="rest")
    pos = traj["labels"][f].astype(bool)
    ax.scatter(*now[~pos].T, s=10, c="tab:red", label="deformed")
    if pos.any():
        ax.scatter(*now[pos].T, s=14, c="m", label="label 1")
    d = (now - rest) * ARROW_GAIN
    ax.quiver(rest[:, 0], rest[:, 1], d[:, 0], d[:, 1], angles="xy", scale_units="xy", scale=1,
              width=0.003, color="tab:red", alpha=0.6)
    if traj["contact"][f]:
        ax.plot(*traj["centreline_px"][f].T, c="tab:blue", lw=1, label="vessel")
    mean_disp = np.linalg.norm(now - rest, axis=1).mean()
    ax.set_title(f"{title}\nframe {traj['frame_index'][f]}, mean |d| {mean_disp:.1f} px", fontsize=8)
    ax.set_xlim(DEFAULT_CAMERA.cx_px - 400, DEFAULT_CAMERA.cx_px + 400)
    ax.set_ylim(DEFAULT_CAMERA.cy_px + 400, DEFAULT_CAMERA.cy_px - 400)  # image y down
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def draw_frame(traj: dict, f: int, name: str) -> np.ndarray:
    """One BGR video frame (scaled) of markers, labels and, in contact, the vessel centreline."""
    w, h = IMAGE_SIZE_PX
    s = VIDEO_SCALE
    img = np.zeros((int(h * s), int(w * s), 3), np.uint8)
    c = tuple(int(round(v * s)) for v in DEFAULT_CAMERA.centre)
    cv2.circle(img, c, int(DEFAULT_CAMERA.circle_radius_px * s), (80, 80, 80), 1, cv2.LINE_AA)
    if traj["contact"][f]:
        line = np.round(traj["centreline_px"][f] * s).astype(np.int32)
        cv2.polylines(img, [line], False, (255, 160, 0), 2, cv2.LINE_AA)
    for p, q, lab in zip(traj["rest_markers_px"], traj["markers"][f], traj["labels"][f]):
        cv2.circle(img, (int(p[0] * s), int(p[1] * s)), 4, (110, 110, 110), 1, cv2.LINE_AA)
        colour = (255, 0, 255) if lab else (60, 60, 255)
        cv2.circle(img, (int(q[0] * s), int(q[1] * s)), 4, colour, -1, cv2.LINE_AA)
    text = f"{name}  frame {traj['frame_index'][f]}  contact {int(traj['contact'][f])}"
    cv2.putText(img, text, (12, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (230, 230, 230), 1, cv2.LINE_AA)
    return img


def markers_figure(trajectories: list[tuple[str, dict]], stem: str | os.PathLike) -> list[Path]:
    """One panel per trajectory at its deepest frame; PNG + PDF."""
    fig, axes = plt.subplots(1, len(trajectories), figsize=(3.2 * len(trajectories), 3.6), squeeze=False)
    for ax, (name, traj) in zip(axes[0], trajectories):
        plot_markers(ax, traj, name)
    axes[0, 0].legend(loc="lower left", fontsize=6)
    fig.suptitle(f"Twin markers at the deepest frame: rest (grey) vs deformed (red), arrows x{ARROW_GAIN:g}",
                 fontsize=9)
    out = save_figure(fig, stem)
    plt.close(fig)
    return out


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
