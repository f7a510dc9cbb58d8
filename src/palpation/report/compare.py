"""Reading the workflow's tables for the results page, and comparing our numbers with the paper's.

Every table is checked when it is read: a missing required column raises one ValueError naming the
file, the column and the rule that writes it, so a stale or hand-edited table fails with a message
instead of a KeyError deep in the page builder. A table that is absent is simply `None` (that profile
did not produce it); the page then says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import pandas as pd

from palpation.metrics.aggregate import summarise_seeds
from palpation.readers import read_csv
from palpation.readers import read_json as read_json_file


class Source(NamedTuple):
    path: str  # relative to the results root
    columns: tuple[str, ...]  # columns the page reads
    rule: str  # the rule that writes it, for messages


SOURCES = {
    "data": Source("data/summary.csv", ("dataset", "trials", "frames", "positive_rate"), "data_summary"),
    "calibration": Source("calibration/calibration.csv", ("interaction", "undeformed_px", "fitted_px", "fitted_mm"),
                          "calibrate"),
    "loop": Source("loop/loop_real.csv", ("round", "effect_added", "mae_fit_px", "mae_heldout_px", "mae_mean_mm"),
                   "loop"),
    "seed_sweep": Source("train/report/seed_sweep.csv", ("config", "seed", "auroc", "ap", "fg_iou", "bg_iou",
                                                         "chance"), "train_report"),
    "table3": Source("train/report/clip_len_ablation.csv", ("clip_len", "seed", "fg_iou", "ap"), "train_report"),
    "table4_markers": Source("train/report/table4_markers.csv", ("config", "seed", "tp", "fp", "fn", "tn", "mcc",
                                                                 "f1", "precision", "recall", "fg_iou", "bg_iou",
                                                                 "ap"), "train_report"),
    "table4_maps": Source("maps/table4_maps.csv", ("config", "threshold", "threshold_rule", "tp", "fp", "fn", "tn",
                                                   "mcc", "f1", "precision", "recall", "fg_iou", "bg_iou", "ap",
                                                   "d_bar_mm"), "vessel_maps"),
    "maps_photo": Source("maps/table4_maps_photo.csv", ("config", "threshold", "threshold_rule", "tp", "fp", "fn",
                                                        "tn", "precision", "recall", "d_bar_mm"), "vessel_maps"),
    "twin_ablation": Source("train/report/twin_ablation.csv",
                            ("dataset_twin", "experiment", "n_seeds", "auroc_mean", "auroc_std", "ap_mean", "ap_std",
                             "fg_iou_mean", "bg_iou_mean"), "of the twin ablation (TWIN_ABLATION_FILES)"),
    "recipe_ablation": Source("recipe/report/recipe_ablation.csv",
                              ("config", "recipe", "switch_off", "seeds", "auroc_mean", "auroc_std", "ap_mean", "ap_std",
                               "pos_share_05", "ece", "d_bar_mm"), "recipe_report"),
    "recipe_crossfit": Source("recipe/report/recipe_calibration_crossfit.csv",
                              ("config", "recipe", "switch_off", "calibration", "fitted_on", "seeds", "ece", "ece_std",
                               "pos_share_05", "brier", "ap", "d_bar_mm", "map_recall", "map_pred_px",
                               "map_threshold_from", "d_bar_05_mm", "map_recall_05", "d_bar_05_seeds"),
                              "recipe_crossfit"),
    "loop_slides": Source("loop_slides/loop_slides.csv", ("fold", "round", "effect_added", "mae_fit_px", "mae_heldout_px",
                                                         "vessel_ratio_sim", "vessel_ratio_real"), "slide_loop"),
    "twin_selection": Source("judge/twin_selection.csv",
                             ("twin", "fitted_on", "heldout_slide_mae_px", "vessel_ratio_sim", "vessel_ratio_real",
                              "silicone_ap_crossfit", "silicone_auroc_crossfit", "meat_ap", "meat_auroc",
                              "silicone_pos_share_05", "seeds", "chosen"), "twin_selection"),
    "transfer": Source("transfer/transfer.csv", ("config", "method", "selection", "transductive", "chosen", "seeds",
                                                 "ap_mean", "ap_std", "auroc_mean", "pos_share_05"),
                       "workflow/scripts/gpu_transfer.sh (docs/transfer.md)"),
    "drift_bounds": Source("judge/drift_bounds.csv", ("predictor", "uses_heldout_truth", "heldout_mae_px",
                                                      "change_vs_no_motion"), "twin_selection"),
}

TITLES = {
    "data": "Data sets",
    "calibration": "Calibration (Fig. 4, MAE table)",
    "loop": "Residual loop (beyond the paper)",
    "seed_sweep": "Seed sweep (Fig. 6 numbers)",
    "table3": "Table 3: clip length",
    "table4_markers": "Table 4, upper half: per marker",
    "table4_maps": "Table 4, lower half: vessel maps",
    "twin_ablation": "Twin ablation: which twin made the Sim set",
    "recipe_ablation": "Training recipe: reference vs robust (issue 15)",
    "recipe_crossfit": "Training recipe: calibration cross-fitted between the real sets (issue 15)",
    "twin_selection": "Twin on the task (issue 12)",
    "transfer": "Transfer beyond the paper: selection on the other real set, unlabelled real motion",
}


def read_table(root: str | Path, key: str) -> pd.DataFrame | None:
    """The table `key` of SOURCES under `root`, or None if the run did not produce it."""
    src = SOURCES[key]
    path = Path(root) / src.path
    if not path.exists():
        return None
    return read_csv(path, src.columns, f"rerun rule {src.rule} with the current code")


def read_json(path: str | Path):
    """A JSON file's content, or None if it does not exist."""
    return read_json_file(path, "rerun the rule that writes it (conf/results_page/folders.yaml names the rules of each "
                          "folder)", optional=True)


@dataclass(frozen=True)
class Comparison:
    """ours − paper, and the same difference in units of the combined seed std."""

    diff: float
    sigma: float  # sqrt(std_ours² + std_paper²); NaN if either is unknown
    k: float = 2.0  # "within seed noise" means |diff| <= k·sigma
    too_few: str = ""  # why no verdict is given (too few seeds, no spread); empty when one is

    @property
    def z(self) -> float:
        return abs(self.diff) / self.sigma if self.sigma > 0 else math.nan

    @property
    def within(self) -> bool | None:
        """None where no noise scale exists (one seed, or a single instance)."""
        if math.isnan(self.sigma) or self.too_few:
            return None
        return abs(self.diff) <= self.k * self.sigma

    def verdict(self) -> str:
        if self.too_few:
            return self.too_few
        if self.within is None:
            return "no seed spread to judge by"
        side = "higher" if self.diff > 0 else "lower"
        if self.sigma == 0:
            return "equal" if self.diff == 0 else f"{side}; both spreads zero"
        if self.within:
            return f"within seed noise ({self.z:.1f}σ)"
        return f"**{self.z:.1f}σ {side}**"


MIN_SEEDS = 3  # a seed verdict needs at least this many seeds of ours and a non-zero spread


def compare(ours: float, ours_std: float, paper: float, paper_std: float, k: float = 2.0,
            n_ours: int | None = None) -> Comparison:
    """`n_ours`: our seeds behind `ours_std`; with fewer than MIN_SEEDS or a zero spread no verdict is given
    (two seeds that agree by chance would turn any difference into many σ)."""
    sigma = math.hypot(ours_std, paper_std) if not (math.isnan(ours_std) or math.isnan(paper_std)) else math.nan
    too_few = ""
    if n_ours is not None and n_ours < MIN_SEEDS:
        too_few = f"too few seeds to judge ({n_ours}; {MIN_SEEDS} needed)"
    elif n_ours is not None and ours_std == 0:
        too_few = f"no spread over our {n_ours} seeds to judge by"
    return Comparison(float(ours) - float(paper), sigma, k, too_few)


def seed_stats(values) -> tuple[float, float, int]:
    """mean, sample std (ddof 1; NaN for one seed) and n."""
    s = summarise_seeds(values)
    return s["mean"], s["std"], s["n"]


@dataclass(frozen=True)
class Gap:
    """One ours-vs-paper difference, for the explanations' conditions."""

    config: str | None  # configuration, data set or interaction the row is about
    metric: str
    diff: float  # ours − paper (or the row's own difference, e.g. loop − calibrated)
    within: bool | None  # within seed noise; None where no noise scale exists


def truthy(v) -> bool:
    """A CSV cell read as a flag: "true" / "1" (any case) is true."""
    return str(v).strip().lower() in ("true", "1")


def aim_miss(value: float, sense: str, target: float) -> float:
    """How far `value` misses an issue's aim `sense target` (">=" or "<="); 0 where it is met."""
    return max(0.0, target - value) if sense == ">=" else max(0.0, value - target)


def aim_lines(checks, label) -> tuple[list[str], list[Gap]]:
    """Bullets and gaps of aim checks (row, column, value, sense, target, miss); `label(row)` names the row."""
    bullets, gaps = [], []
    for row, col, v, sense, target, miss in checks:
        state = "met" if miss == 0 else f"**missed by {miss:.3g}**"
        bullets.append(f"{label(row)}: {col} {v:.3g} (aim {sense} {target:g}): {state}.")
        gaps.append(Gap(row, col, -miss if sense == ">=" else miss, miss == 0))
    return bullets, gaps


@dataclass
class Section:
    """One table of the page: its Markdown, the generated bullets and the differences behind them."""

    key: str  # the table's key in SOURCES and in the explanations file
    title: str
    body: str
    bullets: list[str]
    gaps: list[Gap]
    configs: set[str]  # rows present (configurations, data sets, interactions)
