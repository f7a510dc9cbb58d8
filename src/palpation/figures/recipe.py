"""Issue 15 figures: reliability diagrams per test set, and the seed-ensemble vessel map beside Fig. 7
(mean score, seed spread, the map with unsure pixels, and the coverage-precision curve)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from palpation.mapping.uncertainty import COLOURS, EnsembleMap  # noqa: E402
from palpation.metrics.calibration import ece, reliability  # noqa: E402

LABELS = ("TP", "FP", "FN", "TN", "unsure")


def draw_reliability(ax, probs, labels, name: str, n_bins: int = 15) -> None:
    """Positive share against mean score per bin (marker size ∝ bin count), the diagonal, the ECE."""
    r = reliability(probs, labels, n_bins)
    used = r["count"] > 0
    size = 8 + 120 * r["count"][used] / r["count"].max()
    ax.plot(r["confidence"][used], r["frequency"][used], "-", lw=1)
    ax.scatter(r["confidence"][used], r["frequency"][used], s=size, zorder=3,
               label=f"{name}: ECE {ece(probs, labels, n_bins):.3f}")


def reliability_figure(panels: dict[str, dict[str, tuple]], title: str = ""):
    """panels: test set title -> {curve name (e.g. 'reference', 'robust'): (probs, labels)}; one axis each."""
    fig, axes = plt.subplots(1, len(panels), figsize=(3.8 * len(panels), 3.8), squeeze=False, layout="constrained")
    for ax, (panel, curves) in zip(axes[0], panels.items()):
        ax.plot([0, 1], [0, 1], color="0.6", ls="--", lw=1, label="perfectly calibrated")
        for name, (probs, labels) in curves.items():
            draw_reliability(ax, probs, labels, name)
        ax.set(xlim=(0, 1), ylim=(0, 1), xlabel="mean predicted probability in bin",
               ylabel="share of positive markers in bin", title=panel)
        ax.legend(loc="upper left", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    return fig


def _tiled(arr: np.ndarray, gap_value) -> np.ndarray:
    """(M, H, W[, 3]) -> maps with a 2-px gap, side by side (tall maps) or stacked (wide maps)."""
    axis = 0 if arr.shape[2] > arr.shape[1] else 1
    gap_shape = list(arr.shape[1:])
    gap_shape[axis] = 2
    gap = np.full(gap_shape, gap_value, arr.dtype)
    parts = []
    for i, a in enumerate(arr):
        parts += ([gap] if i else []) + [a]
    return np.concatenate(parts, axis=axis)


def uncertainty_figure(maps: dict[str, EnsembleMap], curves: dict[str, list[dict]], title: str = ""):
    """One row per configuration: ensemble mean, spread, classes with unsure pixels; last column the
    coverage-precision curves of all configurations."""
    n = len(maps)
    fig, axes = plt.subplots(n, 4, figsize=(15, 2.8 * n + 0.6), squeeze=False, layout="constrained")
    for row, (config, ens) in zip(axes, maps.items()):
        mean = np.where(ens.visited, ens.mean, np.nan)
        im = row[0].imshow(_tiled(mean, np.nan), vmin=0, vmax=1, cmap="viridis", interpolation="nearest")
        fig.colorbar(im, ax=row[0], label="ensemble mean probability", shrink=0.8)
        spread = np.where(ens.visited, ens.spread, np.nan)
        im = row[1].imshow(_tiled(spread, np.nan), vmin=0, vmax=max(float(np.nanmax(spread)), 1e-3), cmap="magma",
                           interpolation="nearest")
        fig.colorbar(im, ax=row[1], label="seed std", shrink=0.8)
        row[2].imshow(_tiled(ens.rgb(), 128), interpolation="nearest")
        row[2].legend(handles=[Patch(color=c / 255, label=lab) for c, lab in zip(COLOURS, LABELS)],
                      fontsize=6, loc="upper center", bbox_to_anchor=(0.5, -0.02), ncol=5, frameon=False)
        row[0].set_ylabel(f"{config}\n({ens.n_seeds} seeds), 1 px = 1 mm")
        for ax, t in zip(row[:3], ("mean", "spread", f"map at {ens.threshold:g}, unsure = mean ± std crosses it")):
            ax.set_title(t, fontsize=8)
            ax.set_xticks([]), ax.set_yticks([])
        row[3].axis("off")
    ax = axes[0, 3]
    ax.axis("on")
    for config, rows in curves.items():
        ax.plot([r["coverage"] for r in rows], [r["precision"] for r in rows], "o-", label=config)
    ax.set(xlim=(1.02, 0.0), ylim=(0, 1.02), xlabel="coverage (share of visited pixels committed to)",
           ylabel="precision of committed positive pixels", title="coverage-precision")
    ax.legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    return fig
