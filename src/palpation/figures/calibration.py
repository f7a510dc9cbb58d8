"""Calibration figures: Fig. 4 (simulated vs real markers per interaction) and the search history."""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Mapping, Sequence

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import optuna  # noqa: E402

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


def plot_history(study: optuna.Study, n_startup: int, out_stem: str | os.PathLike, baseline: float | None = None,
                 ylabel: str = "objective", title: str = "") -> list[Path]:
    """Optuna's optimisation history (every trial's value, the best so far) with the random startup trials
    shaded, diverged simulations (the configured worst value) crossed out and the undeformed sensor's MAE."""
    with matplotlib.rc_context(), warnings.catch_warnings():  # optuna sets the ggplot style globally
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        ax = optuna.visualization.matplotlib.plot_optimization_history(study, target_name=ylabel)
        done = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
        div = [t for t in done if t.user_attrs.get("diverged")]
        if div:
            ax.scatter([t.number for t in div], [t.value for t in div], c="k", marker="x", s=30, zorder=3,
                       label="diverged")
        if n_startup and done:
            ax.axvspan(-0.5, min(n_startup, len(done)) - 0.5, color="tab:blue", alpha=0.08,
                       label="random (startup)")
        if baseline is not None:
            ax.axhline(baseline, color="0.4", ls="--", lw=1, label=f"undeformed sensor ({baseline:.2f})")
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))  # trial numbers
        ax.legend(fontsize=7)
        ax.set_title(title, fontsize=8)
        fig = ax.figure
        fig.set_size_inches(5.0, 3.4)
        paths = save_figure(fig, out_stem, dpi=200)
    plt.close(fig)
    return paths
