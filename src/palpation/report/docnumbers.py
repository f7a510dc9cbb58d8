"""Every number the README and docs/*.md state, each read from a committed record under docs/results/.

`NUMBERS` maps a block key to a function of the records folder that returns the block's text; the blocks
themselves (`<!-- gen:KEY -->...<!-- /gen -->`) are filled by `report.docblocks`. A new number in the docs is
one entry here, reading its record, never a typed figure. The paper's published numbers come from
`report.paper`, their one owner.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from palpation.readers import read_csv, read_json
from palpation.report import paper

FIX = "restore it from git (docs/results/ holds the committed records the docs quote)"
CONFIGS = tuple(paper.CONFIG_TITLES)


def _csv(results: Path, name: str, columns: tuple[str, ...]):
    return read_csv(results / name, columns, fix=FIX, what="record")


def seed_stats(results: Path, name: str, config: str, metric: str, digits: int) -> str:
    """Mean ± standard deviation (ddof 1) over a sweep's seeds, as the results page states them."""
    values = _csv(results, name, ("config", "seed", metric)).query("config == @config")[metric]
    if values.empty:
        raise ValueError(f"record {results / name} has no row of config {config}; regenerate the record")
    return f"{values.mean():.{digits}f} ± {values.std():.{digits}f}"


def paper_stats(config: str, metric: str) -> str:
    mean, std = paper.SEED_SWEEP[config][metric]
    digits = paper.PAPER_DIGITS.get(config, 4)
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def headline_table(results: Path) -> str:
    """The paper profile's five-seed sweep and vessel maps beside the paper's (Table 4, §15.1)."""
    maps = _csv(results, "table4_maps.csv", ("config", "d_bar_mm")).set_index("config")["d_bar_mm"]
    rows = ["| configuration | AUROC here | AUROC paper | AP here | AP paper | map d̄ here (mm) "
            "| map d̄ paper (mm) |", "|---|---|---|---|---|---|---|"]
    for c in CONFIGS:
        rows.append(f"| {paper.CONFIG_TITLES[c]} ({c}) | {seed_stats(results, 'seed_sweep.csv', c, 'auroc', 4)} | "
                    f"{paper_stats(c, 'auroc')} | {seed_stats(results, 'seed_sweep.csv', c, 'ap', 4)} | "
                    f"{paper_stats(c, 'ap')} | {maps[c]:.2f} | {paper.TABLE4_MAPS[c]['d_bar_mm']:.2f} |")
    return "\n".join(rows)


def quick_table(results: Path) -> str:
    """What `make reproduce` (quick profile, 2 CPU cores) gives: the committed reference of its contract."""
    name = "reproduce/quick/seed_sweep.csv"
    rows = ["| configuration | AUROC | AP |", "|---|---|---|"]
    rows += [f"| {paper.CONFIG_TITLES[c]} ({c}) | {seed_stats(results, name, c, 'auroc', 3)} | "
             f"{seed_stats(results, name, c, 'ap', 3)} |" for c in CONFIGS]
    return "\n".join(rows)


def calibration_mae(results: Path, column: str, unit: str = "px") -> str:
    """Mean over the interactions of calibration.csv's `column` (the fitted twin, or a sensor that never moves)."""
    value = _csv(results, "calibration.csv", ("interaction", column))[column].mean()
    return f"{value:.2f} px" if unit == "px" else f"{value:.2f} mm"


def loop_change(results: Path, column: str, unit: str, digits: int) -> str:
    """First round → last round of the residual loop on the real photos (loop_real.csv)."""
    values = _csv(results, "loop_real.csv", ("round", column)).sort_values("round")[column]
    return f"{values.iloc[0]:.{digits}f} → {values.iloc[-1]:.{digits}f} {unit}"


def loop_effects(results: Path) -> str:
    effects = _csv(results, "loop_real.csv", ("round", "effect_added")).sort_values("round")["effect_added"]
    return ", then ".join(f"`{e}`" for e in effects if e != "none")


def twin_choice(results: Path) -> str:
    """Each candidate twin's held-out real-slide MAE and the choice (twin_selection.csv)."""
    table = _csv(results, "twin_selection.csv", ("twin", "heldout_slide_mae_px", "chosen", "p_vs_simpler"))
    parts = [f"{r.twin} {r.heldout_slide_mae_px:.4f} px" + ("" if r.chosen else f" (p {r.p_vs_simpler:.2f})")
             for r in table.itertuples()]
    chosen = table.loc[table["chosen"].astype(str) == "True", "twin"]
    if len(chosen) != 1:
        raise ValueError(f"record {results / 'twin_selection.csv'} marks {len(chosen)} twins chosen, not one")
    return f"{', '.join(parts)}: `{chosen.iloc[0]}` chosen"


def twin_ablation(results: Path) -> str:
    table = _csv(results, "twin_ablation.csv", ("dataset_twin", "auroc_mean", "ap_mean"))
    return ", ".join(f"{r.dataset_twin} twin {r.auroc_mean:.4f} / {r.ap_mean:.4f}" for r in table.itertuples())


def last_wall_time(results: Path, profile: str) -> str:
    """The last whole-workflow wall time of a profile (bench_reproduction.json, one record per run)."""
    records = [r for r in read_json(results / "bench_reproduction.json", FIX, "record", kind=list)
               if r.get("profile") == profile]
    if not records:
        raise ValueError(f"record {results / 'bench_reproduction.json'} holds no {profile}-profile run")
    device = records[-1]["device"]
    where = "2 CPU cores" if device.startswith("cpu") else device.removeprefix("cuda:").removeprefix("NVIDIA ")
    return f"{records[-1]['wall_s']:.0f} s ({where})"


def twin_batch_time(results: Path, kernel: str) -> str:
    """500 reference-resolution slides of 398 frames on an H100 (bench_twin.json), by kernel."""
    def fits(r: dict) -> bool:
        variant = kernel == "streamed" or r.get("resident_variant") == "compact"  # the variant the profiles run
        return (r.get("kernel", "streamed") == kernel and variant and r["n_envs"] == 500
                and r["resolution"] == "reference" and "H100" in r["device"])

    records = [r for r in read_json(results / "bench_twin.json", FIX, "record", kind=list) if fits(r)]
    if not records:
        raise ValueError(f"record {results / 'bench_twin.json'} holds no H100 500-slide run of kernel {kernel}")
    return f"{records[-1]['wall_s_measured']:.1f} s"


NUMBERS: dict[str, Callable[[Path], str]] = {
    "headline": headline_table,
    "quick": quick_table,
    "calibration.fitted": lambda r: calibration_mae(r, "fitted_px"),
    "calibration.fitted_mm": lambda r: calibration_mae(r, "fitted_mm", "mm"),
    "calibration.undeformed": lambda r: calibration_mae(r, "undeformed_px"),
    "calibration.paper": lambda r: f"{paper.CALIBRATION_MEAN['twin']:.2f} px",
    "loop.effects": loop_effects,
    "loop.mae_mm": lambda r: loop_change(r, "mae_mean_mm", "mm", 3),
    "loop.heldout": lambda r: loop_change(r, "mae_heldout_px", "px", 2),
    "twin_choice": twin_choice,
    "twin_ablation": twin_ablation,
    "wall.quick": lambda r: last_wall_time(r, "quick"),
    "wall.paper": lambda r: last_wall_time(r, "paper"),
    "twin.streamed": lambda r: twin_batch_time(r, "streamed"),
    "twin.resident": lambda r: twin_batch_time(r, "resident"),
}
