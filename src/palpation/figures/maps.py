"""Fig. 7: confusion maps per configuration and the threshold-selection plot (SPEC §12 colours).

TP green, FP blue, FN red, TN black; `_big` images are the raw maps enlarged x5 nearest-neighbour.
Several maps of one configuration (Meat trials, Sim slides) are tiled left to right with a grey gap.
"""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from palpation.io import atomic_path, save_figure  # noqa: E402

COLOURS = {"tp": (0, 200, 0), "fp": (40, 90, 255), "fn": (230, 0, 0), "tn": (0, 0, 0)}
LABELS = {"tp": "TP: vessel found", "fp": "FP: false alarm", "fn": "FN: vessel missed", "tn": "TN / not visited"}
GAP_RGB = (128, 128, 128)
BIG = 5
MM_PER_PX = 1.0  # the top-view grids' resolution (mapping/grid.py)
SCALE_BAR_MM = 20


def confusion_rgb(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(H, W) masks -> (H, W, 3) uint8 confusion image."""
    pred, truth = np.asarray(pred, bool), np.asarray(truth, bool)
    rgb = np.zeros(pred.shape + (3,), np.uint8)
    for key, mask in (("tp", pred & truth), ("fp", pred & ~truth), ("fn", ~pred & truth)):
        rgb[mask] = COLOURS[key]
    return rgb


def tile(images: list[np.ndarray], gap: int = 2, per_row: int = 5) -> np.ndarray:
    """Maps side by side, `per_row` per row, separated by grey gaps."""
    h, w = images[0].shape[:2]
    n_rows = -(-len(images) // per_row)
    n_cols = min(len(images), per_row)
    out = np.empty((n_rows * h + (n_rows - 1) * gap, n_cols * w + (n_cols - 1) * gap, 3), np.uint8)
    out[:] = GAP_RGB
    for i, im in enumerate(images):
        r, c = divmod(i, per_row)
        out[r * (h + gap):r * (h + gap) + h, c * (w + gap):c * (w + gap) + w] = im
    return out


def confusion_mosaic(score, visited, truth, threshold: float) -> np.ndarray:
    score, visited, truth = (np.asarray(a) for a in (score, visited, truth))
    pred = visited & (score >= threshold)
    return tile([confusion_rgb(p, t) for p, t in zip(pred, truth)])


def save_rgb(image: np.ndarray, path: str | os.PathLike, scale: int = 1) -> Path:
    """Write an RGB image as PNG (atomically), optionally enlarged nearest-neighbour."""
    if scale > 1:
        image = np.repeat(np.repeat(image, scale, axis=0), scale, axis=1)
    with atomic_path(path, suffix=".png") as tmp:
        mpimg.imsave(tmp, image, format="png")
    return Path(path)


def draw_confusion(ax, image: np.ndarray, title: str) -> None:
    """A confusion mosaic with axes in mm (1 px = 1 mm) and a scale bar."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    h, w = image.shape[:2]
    ax.imshow(image, interpolation="nearest", extent=(0, w * MM_PER_PX, h * MM_PER_PX, 0))
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("mm (maps tiled left to right, 2 mm grey gaps)", fontsize=7)
    ax.set_ylabel("mm", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.add_artist(AnchoredSizeBar(ax.transData, SCALE_BAR_MM, f"{SCALE_BAR_MM} mm", "lower right", pad=0.3,
                                  color="white", frameon=False, size_vertical=1, fontproperties={"size": 7}))


def confusion_legend(fig) -> None:
    """The colour key as a legend (not title text)."""
    from matplotlib.patches import Patch

    handles = [Patch(facecolor=np.array(COLOURS[k]) / 255, edgecolor="0.5", label=LABELS[k]) for k in COLOURS]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8, frameon=False)


def draw_threshold(ax, curve: dict, op, title: str) -> None:
    """Precision and recall (3 mm tolerance) against the threshold, with the chosen operating point."""
    t = curve["threshold"]
    ax.plot(t, curve["precision"], color="tab:blue", lw=1.2, label="precision (3 mm)")
    ax.plot(t, curve["recall"], color="tab:orange", lw=1.2, label="recall (3 mm)")
    ax.plot(t, curve["f1"], color="tab:gray", lw=0.8, ls=":", label="F1 (3 mm)")
    ax.axhline(op.min_precision, color="tab:blue", lw=0.6, ls="--",
               label=f"required precision ({op.min_precision:g})")
    ax.axvline(op.threshold, color="k", lw=0.8)
    ax.plot([op.threshold], [op.precision], "o", color="tab:blue", ms=4)
    ax.plot([op.threshold], [op.recall], "o", color="tab:orange", ms=4)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("score threshold")
    ax.set_ylabel("precision, recall, F1 (3 mm tolerance)", fontsize=8)
    ax.set_title(f"{title}: thr {op.threshold:.4f} ({op.rule})", fontsize=9)


def fig7(panels: list[tuple[str, np.ndarray]], stem: str | os.PathLike, suptitle: str = "") -> list[Path]:
    """Confusion mosaics of every configuration, one row each; PNG + PDF."""
    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 2.8 * len(panels) + 0.4), squeeze=False)
    for ax, (title, image) in zip(axes[:, 0], panels):
        draw_confusion(ax, image, title)
    fig.suptitle(suptitle or "Vessel maps", fontsize=10)
    confusion_legend(fig)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    out = save_figure(fig, stem)
    plt.close(fig)
    return out


def threshold_figure(curves: list[tuple[str, dict, object]], stem: str | os.PathLike) -> list[Path]:
    """One panel per configuration: the threshold-selection curves and the chosen point."""
    n = len(curves)
    cols = min(n, 2)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax, (title, curve, op) in zip(axes.ravel(), curves):
        draw_threshold(ax, curve, op, title)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    out = save_figure(fig, stem)
    plt.close(fig)
    return out
