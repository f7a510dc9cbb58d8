"""Real vs simulated marker motion over one Silicone slide, side by side (issue 12, "Twin on the task").

Each panel draws every marker's path over the trial's frames about its median position (the motion the
slide loop scores), magnified, at the marker's median position; markers labelled over a vessel in any frame
of the trial are red, the others grey. Left: the real frames; right: the twin's replay of the same poses.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from palpation.figures.loop import sensor_frame  # noqa: E402
from palpation.io import save_figure  # noqa: E402
from palpation.slides.replay import motion  # noqa: E402


def _panel(ax, markers: np.ndarray, over: np.ndarray, gain: float, title: str) -> None:
    centre = np.median(markers, axis=0)  # (127, 2)
    path = centre[None] + gain * motion(markers[None])[0]  # (F, 127, 2)
    for i in range(markers.shape[1]):
        colour = "#cc3311" if over[i] else "0.55"
        ax.plot(path[:, i, 0], path[:, i, 1], "-", lw=0.8 if over[i] else 0.5, color=colour)
        ax.plot(path[-1, i, 0], path[-1, i, 1], ".", ms=2, color=colour)
    sensor_frame(ax, title)


def slide_motion_figure(real: np.ndarray, sim: np.ndarray, labels: np.ndarray, path_stem, title: str,
                        gain: float = 10.0) -> list:
    """real, sim (F, 127, 2) px of one trial; labels (F, 127) 0/1 (over-vessel). PNG + PDF at `path_stem`."""
    real, sim = np.asarray(real, np.float64), np.asarray(sim, np.float64)
    if real.shape != sim.shape or real.shape[1:] != (127, 2) or labels.shape != real.shape[:2]:
        raise ValueError(f"slide motion figure: real {real.shape}, sim {sim.shape} and labels {labels.shape} "
                         "must be (F, 127, 2), (F, 127, 2), (F, 127) of one trial")
    over = (np.asarray(labels) == 1).any(axis=0)
    real_px = np.linalg.norm(motion(real[None])[0], axis=-1).mean()
    sim_px = np.linalg.norm(motion(sim[None])[0], axis=-1).mean()
    fig, axes = plt.subplots(1, 2, figsize=(7.2, 3.8))
    _panel(axes[0], real, over, gain, f"real: mean motion {real_px:.2f} px")
    _panel(axes[1], sim, over, gain, f"twin: mean motion {sim_px:.2f} px")
    fig.suptitle(f"{title} (paths about each marker's median, x{gain:g}; red: over a vessel)", fontsize=8)
    out = save_figure(fig, path_stem)
    plt.close(fig)
    return out
