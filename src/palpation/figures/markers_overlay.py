"""Figure: ordered markers over each flat-tip photo (index numbers, coloured by ring), one panel each."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from palpation.io import save_figure  # noqa: E402
from palpation.markers.detect import CIRCLE_CENTRE_PX, CIRCLE_RADIUS_PX, load_gray  # noqa: E402
from palpation.markers.lattice import RING_INDEX  # noqa: E402
from palpation.measured import MeasuredSet  # noqa: E402


def draw_markers(ax, image: np.ndarray, markers: np.ndarray, title: str, rest: np.ndarray | None = None,
                 labels: bool = True):
    """Photo cropped to the image circle, markers coloured by ring, optional displacement arrows."""
    cx, cy = CIRCLE_CENTRE_PX
    r = CIRCLE_RADIUS_PX + 15
    ax.imshow(image, cmap="gray", vmin=0, vmax=255)
    if rest is not None:  # displacement from the rest state, drawn x1 (px)
        ax.quiver(rest[:, 0], rest[:, 1], markers[:, 0] - rest[:, 0], markers[:, 1] - rest[:, 1],
                  angles="xy", scale_units="xy", scale=1, color="yellow", width=0.003)
    sc = ax.scatter(markers[:, 0], markers[:, 1], c=RING_INDEX, cmap="turbo", s=6, vmin=0, vmax=6)
    if labels:
        for i, (x, y) in enumerate(markers):
            ax.annotate(str(i), (x, y), xytext=(3, -3), textcoords="offset points", fontsize=3,
                        color="cyan")
    ax.set_xlim(cx - r, cx + r)
    ax.set_ylim(cy + r, cy - r)
    ax.set_title(title, fontsize=7)
    ax.set_axis_off()
    return sc


def plot_markers_overlay(mset: MeasuredSet, photos_dir: str | os.PathLike,
                         out_stem: str | os.PathLike) -> list[Path]:
    """Grid of panels (2 x ceil(S/2)), one per state of `mset`; saves PNG + PDF at `out_stem`."""
    n = len(mset)
    cols = int(np.ceil(n / 2))
    fig, axes = plt.subplots(2, cols, figsize=(3.0 * cols + 0.8, 6.6), squeeze=False, layout="constrained")
    for k, (ax, state) in enumerate(zip(axes.flat, mset.states)):
        image = load_gray(Path(photos_dir) / state.source_file)
        disp = np.linalg.norm(mset.displacement[k], axis=1)
        title = (f"{state.name} ({state.trajectory}): {int(mset.found[k].sum())}/127\n"
                 f"|d| median {np.median(disp):.1f}, max {disp.max():.1f} px")
        sc = draw_markers(ax, image, mset.markers[k], title, rest=mset.rest)
    for ax in list(axes.flat)[n:]:
        ax.set_axis_off()
    fig.colorbar(sc, ax=axes, shrink=0.5, label="ring")
    paths = save_figure(fig, out_stem, dpi=300)
    plt.close(fig)
    return paths
