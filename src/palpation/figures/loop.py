"""Figures of the residual loop: residual quivers per photo, mode shares, MAE per round."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from palpation.camera import DEFAULT_CAMERA  # noqa: E402
from palpation.io import save_figure  # noqa: E402
from palpation.loop.residual import MODES, Decomposition  # noqa: E402

MODE_COLOURS = {"translation": "#4477aa", "rotation": "#66ccee", "radial": "#228833",
                "stretch_shear": "#ccbb44", "local": "#ee6677"}


def sensor_frame(ax, title: str) -> None:
    """The dome's region of the sensor image (px, y down, no ticks), equal aspect, a small title."""
    ax.set_xlim(640, 1440)
    ax.set_ylim(990, 180)  # image coordinates: y down
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=8)


def draw_quiver(ax, real_px: np.ndarray, sim_px: np.ndarray, title: str, scale_px: float = 5.0) -> None:
    """Arrows from each real marker along sim - real, magnified `scale_px` times (image y down)."""
    d = np.asarray(sim_px) - np.asarray(real_px)
    ax.add_patch(plt.Circle(DEFAULT_CAMERA.centre, DEFAULT_CAMERA.circle_radius_px, fill=False, lw=0.6,
                            color="0.7"))
    ax.scatter(real_px[:, 0], real_px[:, 1], s=4, c="k")
    ax.quiver(real_px[:, 0], real_px[:, 1], d[:, 0], d[:, 1], angles="xy", scale_units="xy",
              scale=1.0 / scale_px, color="#cc3311", width=0.004)
    sensor_frame(ax, title)


def _caption(dec: Decomposition) -> str:
    s = dec.shares
    return (f"MAE {dec.mae_px:.2f} px | trans {s['translation']:.0%} rot {s['rotation']:.0%} "
            f"rad {s['radial']:.0%}\nstretch {s['stretch_shear']:.0%} local {s['local']:.0%}")


def plot_state(real_px, panels: list[tuple[str, np.ndarray, Decomposition]], stem: Path, scale_px: float = 5.0):
    """One photo: a quiver per twin (e.g. round 0 and the final round), mode shares in the titles."""
    fig, axes = plt.subplots(1, len(panels), figsize=(3.6 * len(panels), 3.9), squeeze=False)
    for ax, (label, sim, dec) in zip(axes[0], panels):
        draw_quiver(ax, real_px, sim, f"{label}\n{_caption(dec)}", scale_px)
    fig.suptitle(f"{panels[0][2].name}: simulated - real (arrows x{scale_px:g})", fontsize=9)
    paths = save_figure(fig, stem)
    plt.close(fig)
    return paths


def draw_shares(ax, decs: list[Decomposition], labels: list[str]) -> None:
    bottom = np.zeros(len(decs))
    energy = np.array([d.energy_px2 / (2 * 127) for d in decs])  # mean squared component, px^2
    for mode in MODES:
        part = np.array([d.shares[mode] for d in decs]) * energy
        ax.bar(range(len(decs)), part, bottom=bottom, color=MODE_COLOURS[mode], label=mode)
        bottom += part
    ax.set_xticks(range(len(decs)))
    ax.set_xticklabels(labels, rotation=45, ha="right", fontsize=7)
    ax.set_ylabel("residual energy per coordinate (px$^2$)")
    ax.legend(fontsize=7)


def plot_shares(decs: list[Decomposition], labels: list[str], stem: Path):
    fig, ax = plt.subplots(figsize=(max(4.0, 0.5 * len(decs) + 2), 3.5))
    draw_shares(ax, decs, labels)
    ax.set_title("residual modes per photo and round", fontsize=9)
    paths = save_figure(fig, stem)
    plt.close(fig)
    return paths


def plot_rounds(rows: list[dict], baseline_px: float, stem: Path):
    """MAE on the fitted and held-out photos per round, with the undeformed-sensor baseline."""
    fig, ax = plt.subplots(figsize=(5.0, 3.2))
    k = [r["round"] for r in rows]
    ax.plot(k, [r["mae_fit_px"] for r in rows], "o-", label="fitted photos")
    ax.plot(k, [r["mae_heldout_px"] for r in rows], "s-", label="held-out photo(s)")
    ax.axhline(baseline_px, color="0.5", ls="--", lw=0.8, label="undeformed sensor (mean)")
    ax.axhline(0.25 * 55 / 2, color="#228833", ls=":", lw=0.8, label="target 0.25 mm")
    ax.set_xticks(k)
    ax.set_xticklabels([f"{r['round']}\n{r['effect_added']}" for r in rows], fontsize=7)
    ax.set_ylabel("marker MAE (px)")
    ax.legend(fontsize=7)
    paths = save_figure(fig, stem)
    plt.close(fig)
    return paths
