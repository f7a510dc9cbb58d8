"""Fig. 6: mean precision-recall curves over seeds, ±1 std band, one panel per configuration (SPEC §11)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from palpation.metrics.aggregate import mean_curve  # noqa: E402
from palpation.report.paper import CONFIG_TITLES  # noqa: E402

CMAP = "viridis"


def draw_pr(ax, curve: dict, chance: float, title: str) -> LineCollection:
    """Mean PR curve coloured by the mean threshold, its ±1 std band and the chance line."""
    x, y = curve["x"], np.clip(curve["mean"], 0, 1)
    ax.fill_between(x, curve["lower"], curve["upper"], color="0.8", lw=0, label="±1 std")
    points = np.stack([x, y], axis=1)[:, None, :]
    lc = LineCollection(np.concatenate([points[:-1], points[1:]], axis=1), cmap=CMAP,
                        norm=plt.Normalize(0.0, 1.0), linewidths=2)
    lc.set_array(curve["threshold"][:-1])
    ax.add_collection(lc)
    ax.axhline(chance, color="k", ls="--", lw=1, label=f"chance {chance:.3f}")
    ax.set(xlim=(0, 1), ylim=(0, 1.02), xlabel="Recall", title=title)
    ax.legend(loc="best", fontsize=8)
    return lc


def pr_figure(curves_by_config: dict[str, list[dict]], chance_by_config: dict[str, float], label: str = ""):
    """curves_by_config: config -> per-seed {recall, precision, threshold}. Returns the figure."""
    n = len(curves_by_config)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n + 1, 3.8), squeeze=False, sharey=True,
                             layout="constrained")
    lc = None
    for ax, (config, curves) in zip(axes[0], curves_by_config.items()):
        mean = mean_curve(curves)
        lc = draw_pr(ax, mean, chance_by_config[config],
                     f"{CONFIG_TITLES.get(config, config)} ({len(curves)} seeds)")
    axes[0, 0].set_ylabel("Precision")
    if lc is not None:
        fig.colorbar(lc, ax=axes[0].tolist(), label="mean threshold", shrink=0.8)
    if label:
        fig.suptitle(label, fontsize=9)
    return fig
