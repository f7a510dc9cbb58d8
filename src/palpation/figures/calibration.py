"""Calibration figures: Fig. 4 (simulated vs real markers per interaction) and the search history."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from palpation.camera import MM_PER_PX  # noqa: E402
from palpation.io import save_figure  # noqa: E402
from palpation.markers.detect import CIRCLE_CENTRE_PX, CIRCLE_RADIUS_PX  # noqa: E402

SIM_COLOUR, REAL_COLOUR = "red", "limegreen"


def draw_marker_pair(ax, real: np.ndarray, sim: np.ndarray, title: str, image: np.ndarray | None = None):
    """One panel: real (green) and simulated (red) markers over the photo, cropped to the image circle."""
    cx, cy = CIRCLE_CENTRE_PX
    r = CIRCLE_RADIUS_PX + 15
    if image is not None:
        ax.imshow(image, cmap="gray", vmin=0, vmax=255)
    else:
        ax.add_patch(plt.Circle((cx, cy), CIRCLE_RADIUS_PX, fill=False, color="0.6", lw=0.8))
        ax.set_aspect("equal")
    ax.scatter(real[:, 0], real[:, 1], s=9, c=REAL_COLOUR, label="real", linewidths=0)
    ax.scatter(sim[:, 0], sim[:, 1], s=9, c=SIM_COLOUR, marker="x", label="twin", linewidths=0.8)
    ax.set_xlim(cx - r, cx + r)
    ax.set_ylim(cy + r, cy - r)
    ax.set_title(title, fontsize=8)
    ax.set_axis_off()


def plot_fig4(real: Mapping[str, np.ndarray], sim: Mapping[str, np.ndarray], mae_px: Mapping[str, float],
              out_stem: str | os.PathLike, images: Mapping[str, np.ndarray] | None = None,
              suptitle: str = "") -> list[Path]:
    """Fig. 4: per interaction, the twin's markers at the deepest point vs the photo's (PNG + PDF)."""
    kinds = list(real)
    fig, axes = plt.subplots(1, len(kinds), figsize=(3.0 * len(kinds), 3.4), squeeze=False,
                             layout="constrained")
    for ax, kind in zip(axes[0], kinds):
        title = f"{kind}: MAE {mae_px[kind]:.2f} px ({mae_px[kind] * MM_PER_PX:.2f} mm)"
        draw_marker_pair(ax, real[kind], sim[kind], title, None if images is None else images.get(kind))
    axes[0, 0].legend(loc="lower left", fontsize=7, framealpha=0.8)
    if suptitle:
        fig.suptitle(suptitle, fontsize=9)
    paths = save_figure(fig, out_stem, dpi=200)
    plt.close(fig)
    return paths


def draw_history(ax, rows: Sequence[Mapping], n_startup: int, maximise: bool, baseline: float | None = None,
                 ylabel: str = "objective"):
    """Trial values (random startup vs guided, diverged marked) and the best so far."""
    done = [r for r in rows if r["state"] == "COMPLETE"]
    x = np.array([r["trial"] for r in done])
    y = np.array([r["value"] for r in done], float)
    div = np.array([bool(r.get("diverged", False)) for r in done])
    startup = np.arange(len(done)) < n_startup
    for mask, label, style in ((startup & ~div, "random (startup)", dict(c="tab:blue")),
                               (~startup & ~div, "GP-guided", dict(c="tab:orange")),
                               (div, "diverged", dict(c="k", marker="x"))):
        if mask.any():
            ax.scatter(x[mask], y[mask], label=label, s=22, zorder=3, **style)
    if len(y):
        best = np.maximum.accumulate(y) if maximise else np.minimum.accumulate(y)
        ax.step(x, best, where="post", color="tab:green", label="best so far")
    if baseline is not None:
        ax.axhline(baseline, color="0.4", ls="--", lw=1, label=f"undeformed sensor ({baseline:.2f})")
    ax.set_xlabel("trial")
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def plot_history(rows: Sequence[Mapping], n_startup: int, maximise: bool, out_stem: str | os.PathLike,
                 baseline: float | None = None, ylabel: str = "objective", title: str = "") -> list[Path]:
    fig, ax = plt.subplots(figsize=(5.0, 3.4), layout="constrained")
    draw_history(ax, rows, n_startup, maximise, baseline, ylabel)
    if title:
        ax.set_title(title, fontsize=8)
    paths = save_figure(fig, out_stem, dpi=200)
    plt.close(fig)
    return paths
