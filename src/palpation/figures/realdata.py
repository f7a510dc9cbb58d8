"""Overviews of the real data sets: Meat viewer states and Silicone frames, markers coloured by label."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from palpation.camera import video_to_sensor_px  # noqa: E402
from palpation.realdata import silicone as sil  # noqa: E402
from palpation.realdata.meat import state_to_trial  # noqa: E402
from palpation.realdata.video import read_states  # noqa: E402


def draw_meat_state(ax, markers: np.ndarray, labels: np.ndarray, template: np.ndarray, title: str) -> None:
    """Markers of one frame in sensor px, coloured by label as in the viewer, over the rest template."""
    ax.scatter(*template.T, s=28, facecolors="none", edgecolors="0.65", linewidths=0.6, label="rest")
    for value, colour in ((0, "c"), (1, "m")):
        ax.scatter(*markers[labels == value].T, s=9, c=colour, label=f"label {value}")
    ax.set_title(f"{title}\n{int(labels.sum())} positive", fontsize=8)
    ax.set_aspect("equal")
    ax.invert_yaxis()  # image coordinates, y down
    ax.tick_params(labelsize=6)


def meat_overview(data: dict[str, np.ndarray], states: list[int], n_cols: int = 3):
    """A grid of `draw_meat_state` panels for a few viewer states."""
    n_rows = -(-len(states) // n_cols)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(3.2 * n_cols, 3.0 * n_rows), squeeze=False)
    for ax, s in zip(axes.flat, states):
        trial, frame = state_to_trial(s)
        draw_meat_state(ax, data["markers"][s], data["labels"][s], data["template"],
                        f"state {s}: trial {trial.trial_id}, frame {frame}\n{trial.description}")
    for ax in axes.flat[len(states):]:
        ax.set_axis_off()
    axes.flat[0].legend(fontsize=6, loc="lower left")
    for ax in axes[-1]:
        ax.set_xlabel("sensor x (px)", fontsize=7)
    for ax in axes[:, 0]:
        ax.set_ylabel("sensor y (px)", fontsize=7)
    fig.tight_layout()
    return fig


def silicone_overview(data: dict, video: Path, pairs: list[tuple[int, int]]):
    """A few frames with markers coloured by label (hollow = filled), dots and their chords."""
    videos = [int(v) for v in data["videos"]]
    pairs = [(v, f) for v, f in pairs if v in videos and f <= data["states"].shape[1]]
    frames = read_states(video, states=[sil.state_index(v, f) for v, f in pairs])
    ncol = 3
    nrow = max(1, -(-len(pairs) // ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 4.2 * nrow), squeeze=False)
    (x0, y0), (x1, y1) = video_to_sensor_px([[0, 0], [1280, 760]])
    for ax, (v, f), frame in zip(axes.ravel(), pairs, frames):
        k, t = videos.index(v), f - 1
        ax.imshow(frame[..., ::-1], extent=(x0, x1, y1, y0), interpolation="bilinear")
        draw_silicone_state(ax, data, k, t)
        ax.set_title(f"video {v} ({sil.SWEEP_NAMES[v - 1]}), frame {f}", fontsize=9)
    for ax in axes.ravel():
        ax.set_xlim(640, 1440), ax.set_ylim(984, 184), ax.set_xticks([]), ax.set_yticks([])
    fig.suptitle("Silicone set: markers by label (magenta 1, cyan 0, hollow = filled), dots and chords")
    fig.tight_layout()
    return fig


def draw_silicone_state(ax, data: dict, k: int, t: int) -> None:
    markers, labels, source = data["markers"][k, t], data["labels"][k, t], data["source"][k, t]
    colour = np.where(labels[:, None] == 1, [[0.9, 0.0, 0.9]], [[0.0, 0.8, 0.9]])
    shown = source > sil.SOURCE_FILLED
    ax.scatter(*markers[shown].T, s=9, c=colour[shown], linewidths=0)
    ax.scatter(*markers[~shown].T, s=30, facecolors="none", edgecolors=colour[~shown], linewidths=1.2,
               zorder=4)  # filled markers lie under a dot: draw them on top
    for dot, c in zip(data["dots"][k, t, :data["dot_counts"][k, t]], data["dot_colours"][k, t]):
        chord = sil.chord_samples(dot, float(data["line_angle_deg"][k]))
        if chord is not None:
            ax.plot(*chord.T, color="yellow", lw=0.8, alpha=0.8)
        ax.scatter(*dot, s=60, c=sil.DOT_COLOURS[c], edgecolors="black", linewidths=1.0, zorder=3)
