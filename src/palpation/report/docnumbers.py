"""Every number the README and docs/*.md state, each read from a committed record under docs/results/.

`NUMBERS` maps a block key to a function of the records folder that returns the block's text; the blocks
themselves (`<!-- gen:KEY -->...<!-- /gen -->`) are filled by `report.docblocks`. A new number in the docs is
one entry here, reading its record, never a typed figure. The paper's published numbers come from
`report.paper`, their one owner.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from palpation.readers import read_json
from palpation.report import paper
from palpation.report.loop_numbers import (
    LOOP_DEV_KEYS, bench_loop, fixed_exact_share, fixed_inlist_unexplained, fixed_summary, general_below_power,
    general_brief, general_by_effect, general_exact_of, general_oracle, general_shared, general_soft_e,
    general_split, general_summary, loop_change, loop_effects, loop_last, loop_rest_ratio, loop_same_table,
    loop_target, reduced_converged, reduced_mae_after, reduced_run_after, selftest_runs,
)
from palpation.report.maps_numbers import SILICONE_MEASURES, silicone_check
from palpation.report.records import FIX, record_csv as _csv
from palpation.report.transfer_numbers import TRANSFER_KEYS
from palpation.report.twin_numbers import (
    binding_offset, stable_dt, stable_dt_table, uniaxial_table, verification,
)

CONFIGS = tuple(paper.CONFIG_TITLES)
QUICK_CALIBRATION = "reproduce/quick/calibration.csv"  # the quick profile's (coarse mesh) committed reference


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


def chance_ap(results: Path, name: str, config: str) -> str:
    """A configuration's chance AP: its test set's positive rate (data, not seeds), as the sweep records it."""
    table = _csv(results, name, ("config", "chance"))
    return f"{table.loc[table['config'] == config, 'chance'].mean():.3f}"


def calibration_mae(results: Path, column: str, unit: str = "px", name: str = "calibration.csv") -> str:
    """Mean over the interactions of calibration.csv's `column` (the fitted twin, or a sensor that never moves)."""
    value = _csv(results, name, ("interaction", column))[column].mean()
    return f"{value:.2f} px" if unit == "px" else f"{value:.2f} mm"


def calibration_margin(results: Path, name: str) -> str:
    """How far the fitted twin's mean marker MAE is below the never-deforming sensor's."""
    table = _csv(results, name, ("interaction", "undeformed_px", "fitted_px"))
    return f"{table['undeformed_px'].mean() - table['fitted_px'].mean():.2f} px"


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


def _bench_twin(results: Path, device: str, n_envs: int, resolution: str, **fields) -> dict:
    """The last bench_twin.json record on `device` (a substring) with these sizes and fields (None: absent)."""
    found = [r for r in read_json(results / "bench_twin.json", FIX, "record", kind=list)
             if device in r["device"] and r["n_envs"] == n_envs and r["resolution"] == resolution
             and all(r.get(k) == v for k, v in fields.items())]
    if not found:
        raise ValueError(f"record {results / 'bench_twin.json'} holds no run on {device} of {n_envs} {resolution} "
                         f"envs with {fields}")
    return found[-1]


def twin_streamed_core(results: Path) -> str:
    r = _bench_twin(results, "H100", 500, "reference", kernel=None)
    return f"core {r['core_substep_us']:.0f} µs a substep, roofline fraction {r['roofline_fraction_streamed']:.2f}"


def twin_resident_times(results: Path) -> str:
    """The resident kernel as the profiles run it (compact@320) and the streamed path, 500 reference envs."""
    def wall(device: str, **fields) -> float:
        return _bench_twin(results, device, 500, "reference", **fields)["wall_s_measured"]

    compact = {"kernel": "resident", "resident_variant": "compact", "block_dim": 320}
    return (f"compact@320 {wall('H200', **compact):.2f} s on an H200 and {wall('H100', **compact):.2f} s on an H100, "
            f"against {wall('H200', kernel='streamed'):.2f} s (H200) and {wall('H100', kernel=None):.2f} s (H100) for "
            f"the streamed path, tiles@512 "
            f"{wall('H200', kernel='resident', resident_variant='tiles', block_dim=512):.2f} s (H200)")


def twin_cpu_auto(results: Path, what: str) -> str:
    """40 coarse slides on the CPU: the streamed kernels against `auto` (resident, one lane a block)."""
    streamed = _bench_twin(results, "cpu", 40, "coarse", kernel="streamed")["wall_s_measured"]
    auto = _bench_twin(results, "cpu", 40, "coarse", kernel="auto")["wall_s_measured"]
    return f"{streamed / auto:.1f}x" if what == "speedup" else f"{streamed:.1f} → {auto:.1f} s"


def train_stacked(results: Path) -> str:
    """Seeds trained together in one process against one after another (bench_train.json)."""
    record = read_json(results / "bench_train.json", FIX, "record", kind=dict, keys=("seeds", "wall_s", "job"))
    wall = record["wall_s"]
    return (f"{len(record['seeds'])} {record['job']['config']} seeds together {wall['together']:.1f} s, one after "
            f"another {wall['apart']:.1f} s")


def _ablation(results: Path, config: str, recipe: str, switch_off: str = "none"):
    table = _csv(results, "recipe_ablation.csv", ("config", "recipe", "switch_off", "seeds", "ap_mean", "ap_std",
                                                   "pos_share_05", "ece"))
    rows = table[(table["config"] == config) & (table["recipe"] == recipe) & (table["switch_off"] == switch_off)]
    if len(rows) != 1:
        raise ValueError(f"record {results / 'recipe_ablation.csv'}: {len(rows)} rows {config}/{recipe}/{switch_off}")
    return rows.iloc[0]


def recipe_ap(results: Path, config: str, recipe: str, switch_off: str = "none") -> str:
    r = _ablation(results, config, recipe, switch_off)
    return f"{r['ap_mean']:.4f} ± {r['ap_std']:.4f}"


def recipe_rows(results: Path) -> str:
    table = _csv(results, "recipe_ablation.csv", ("config", "seeds"))
    seeds = sorted(set(table["seeds"]))
    return f"{len(table)} rows, {'/'.join(map(str, seeds))} seeds each"


def recipe_pair(results: Path, column: str, recipe: str, fmt: str) -> str:
    """Sim→Silicone / Sim→Meat values of one ablation column."""
    return " / ".join(fmt.format(_ablation(results, c, recipe)[column]) for c in ("A-to-B", "A-to-C"))


def recipe_no_rotation(results: Path) -> str:
    """Robust without the consistent rotation: its real AP, which must be each set's worst robust row."""
    table = _csv(results, "recipe_ablation.csv", ("config", "recipe", "switch_off", "ap_mean"))
    parts = []
    for config, title in (("A-to-B", "Silicone"), ("A-to-C", "Meat")):
        robust = table[(table["config"] == config) & (table["recipe"] == "robust")]
        if robust["ap_mean"].idxmin() != robust.index[robust["switch_off"] == "rotation"][0]:
            raise ValueError(f"record {results / 'recipe_ablation.csv'}: robust without rotation is no longer the "
                             f"worst {config} row; docs/recipe.md says it is: revise the text")
        parts.append(f"{title} AP {_ablation(results, config, 'robust', 'rotation')['ap_mean']:.4f}")
    return " and ".join(parts)


def recipe_crossfit_ece(results: Path) -> str:
    table = _csv(results, "recipe_calibration_crossfit.csv", ("config", "recipe", "switch_off", "calibration", "ece"))
    values = []
    for config in ("A-to-B", "A-to-C"):
        rows = table[(table["config"] == config) & (table["recipe"] == "robust") & (table["switch_off"] == "none")
                     & (table["calibration"] == "cross_real")]
        if len(rows) != 1:
            raise ValueError(f"record {results / 'recipe_calibration_crossfit.csv'}: no one cross_real row of {config}")
        values.append(f"{rows['ece'].iloc[0]:.3f}")
    return " / ".join(values)


def slide_gate(results: Path) -> str:
    """What each fold of the slide loop kept, with the inner gate's p (loop_slides.csv)."""
    table = _csv(results, "loop_slides.csv", ("fold", "round", "effect_added", "gate_p"))
    parts = []
    for fold in sorted(set(table["fold"]), key=lambda f: f != "even"):
        kept = table[(table["fold"] == fold) & (table["effect_added"] != "none")]
        parts.append(f"the {fold} fold " + ("nothing" if kept.empty else "keeps " + ", ".join(
            f"{r.effect_added}, p {r.gate_p:.4f}" for r in kept.itertuples())))
    return ", ".join(parts)


def drift_bound(results: Path, predictor: str) -> str:
    """A twin-free predictor of the held-out slide (paper/judge/drift_bounds.csv): the no-motion MAE, or the
    change against it."""
    table = _csv(results, "paper/judge/drift_bounds.csv", ("predictor", "heldout_mae_px", "change_vs_no_motion"))
    rows = table[table["predictor"] == predictor]
    if len(rows) != 1:
        raise ValueError(f"record {results / 'paper/judge/drift_bounds.csv'} has no one row {predictor}")
    if predictor == "no_motion":
        return f"{rows['heldout_mae_px'].iloc[0]:.4f} px"
    change = 100 * rows["change_vs_no_motion"].iloc[0]
    return f"{change:+.{2 if abs(change) < 1 else 1}f} %".replace("-", "−")


def slide_static_offset(results: Path, name: str = "loop_slides.csv") -> str:
    """The slide loop's round 0 (the calibrated twin), held out, mean over the folds: the absolute marker MAE
    against the MAE of the markers' motion about their own medians (loop_slides.csv)."""
    table = _csv(results, name, ("fold", "round", "mae_heldout_px", "mae_abs_heldout_px"))
    first = table[table["round"] == 0]
    if set(first["fold"]) != {"odd", "even"} or len(first) != 2:
        raise ValueError(f"record {results / name} has no round 0 of each fold")
    return f"{first['mae_abs_heldout_px'].mean():.1f} px against {first['mae_heldout_px'].mean():.2f} px of motion"


def twin_choice_slides(results: Path) -> str:
    """The judge's choice and its evidence, as docs/slides.md states it (twin_selection.csv)."""
    table = _csv(results, "twin_selection.csv", ("twin", "heldout_slide_mae_px", "chosen", "p_vs_simpler"))
    chosen = table[table["chosen"].astype(str) == "True"]
    if len(chosen) != 1:
        raise ValueError(f"record {results / 'twin_selection.csv'} marks {len(chosen)} twins chosen, not one")
    others = "; ".join(f"{r.twin} {r.heldout_slide_mae_px:.4f}, p {r.p_vs_simpler:.3f}"
                       for r in table.itertuples() if str(r.chosen) != "True")
    return (f"`{chosen['twin'].iloc[0]}` (`docs/results/twin_selection.csv`: "
            f"{chosen['heldout_slide_mae_px'].iloc[0]:.4f} px; {others})")


def contract_value(results: Path, table: str, column: str, field: str, digits: int, unit: str = "") -> str:
    """A column's measured difference between the two hosts, or its tolerance (contract.json)."""
    tables = read_json(results / "contract.json", FIX, "record", kind=dict, keys=("tables",))["tables"]
    try:
        value = tables[table][column][field]
    except KeyError:
        raise ValueError(f"record {results / 'contract.json'} has no {field} of {table}:{column}") from None
    return f"{value:.{digits}f}" + (f" {unit}" if unit else "")


def contract_identical(results: Path, names: dict[str, str]) -> str:
    """The tables whose every column measured no difference between the hosts, by their docs names."""
    tables = read_json(results / "contract.json", FIX, "record", kind=dict, keys=("tables",))["tables"]
    same = [title for name, title in names.items() if all(c["measured"] == 0 for c in tables[name].values())]
    differ = [title for name, title in names.items() if title not in same]
    return " and ".join(same) + " identical" if not differ else (
        (" and ".join(same) + " identical; " if same else "") + " and ".join(differ) + " not identical")


NUMBERS: dict[str, Callable[[Path], str]] = {
    "headline": headline_table,
    "quick": quick_table,
    "quick.chance_silicone": lambda r: chance_ap(r, "reproduce/quick/seed_sweep.csv", "A-to-B"),
    "calibration.fitted": lambda r: calibration_mae(r, "fitted_px"),
    "calibration.fitted_mm": lambda r: calibration_mae(r, "fitted_mm", "mm"),
    "calibration.undeformed": lambda r: calibration_mae(r, "undeformed_px"),
    "calibration.paper": lambda r: f"{paper.CALIBRATION_MEAN['twin']:.2f} px",
    "loop.effects": loop_effects,
    "loop.mae_mm": lambda r: loop_change(r, "mae_mean_mm", "mm", 3),
    "loop.heldout": lambda r: loop_change(r, "mae_heldout_px", "px", 2),
    "twin_choice": twin_choice,
    "twin_ablation": twin_ablation,
    **TRANSFER_KEYS,
    "wall.quick": lambda r: last_wall_time(r, "quick"),
    "wall.paper": lambda r: last_wall_time(r, "paper"),
    "twin.streamed": lambda r: twin_batch_time(r, "streamed"),
    "twin.resident": lambda r: twin_batch_time(r, "resident"),
    # docs/calibration.md (the coarse mesh: the quick profile's reference record)
    "calibration.quick.undeformed": lambda r: calibration_mae(r, "undeformed_px", name=QUICK_CALIBRATION),
    "calibration.quick.fitted": lambda r: calibration_mae(r, "fitted_px", name=QUICK_CALIBRATION),
    "calibration.quick.margin": lambda r: calibration_margin(r, QUICK_CALIBRATION),
    # docs/loop.md: the mechanisms' reduced self-tests
    "loop.reduced.guard": lambda r: reduced_mae_after(r, "loop_selftest_reduced_before.csv",
                                                      "loop_selftest_reduced_after.csv"),
    "loop.reduced.compete": lambda r: reduced_run_after(r, "loop_selftest_reduced_before3.csv",
                                                        "loop_selftest_reduced_after3.csv", "surface_contact+friction"),
    "loop.reduced.converged": lambda r: reduced_converged(r, "loop_selftest_reduced_before4.csv",
                                                          "loop_selftest_reduced_after4.csv"),
    "loop.fixed.seed2_before": lambda r: fixed_exact_share(r, "loop_selftest_seed2_before.csv"),
    "loop.fixed.camera_grid": lambda r: fixed_exact_share(r, "loop_selftest_camera_grid.csv"),
    "loop.fixed.inlist_unexplained": lambda r: fixed_inlist_unexplained(r, ("loop_selftest.csv",
                                                                            "loop_selftest_seed2.csv")),
    # docs/loop.md: measured behaviour
    "loop.fixed.seed0": lambda r: fixed_summary(r, "loop_selftest.csv"),
    "loop.fixed.seed2": lambda r: fixed_exact_share(r, "loop_selftest_seed2.csv"),
    "loop.fixed.seed7": lambda r: fixed_exact_share(r, "loop_selftest_seed7.csv"),
    "loop.general.runs": lambda r: str(len(selftest_runs(r, "loop_selftest_general_dev_method.csv"))),
    "loop.general.dev": lambda r: general_summary(r, "loop_selftest_general_dev_method.csv"),
    "loop.general.shared": lambda r: general_shared(r, "loop_selftest_general_dev_quick.csv",
                                                    "loop_selftest_general_dev_method.csv"),
    "loop.general.below_power": lambda r: general_below_power(r, "loop_selftest_general_dev_method.csv"),
    "loop.general.soft_e": lambda r: general_soft_e(r, "loop_selftest_general_dev_method.csv",
                                                    "surface_contact+friction+viscous"),
    "loop.general.paper_runs": lambda r: str(len(selftest_runs(r, "loop_selftest_general_dev_paper_partial.csv"))),
    "loop.general.paper_exact": lambda r: general_exact_of(r, "loop_selftest_general_dev_paper_partial.csv"),
    "loop.general.dev1": lambda r: general_summary(r, "loop_selftest_general_dev1_method.csv"),
    "loop.general.dev1_oracle": lambda r: general_oracle(r, "loop_selftest_general_dev1_method.md"),
    "loop.general.test_brief": lambda r: general_brief(r, "loop_selftest_general.csv"),
    **{f"loop.general.test{k}": v for k, v in general_split("loop_selftest_general",
                                                             "loop_selftest_general_test.log").items()},
    **{f"loop.general.prev_test{k}": v for k, v in general_split("loop_selftest_general_seed1002",
                                                                  "loop_selftest_general_seed1002_test.log",
                                                                  ("layered",)).items()},
    **LOOP_DEV_KEYS,
    "loop.bench.quick": lambda r: bench_loop(r, "bench_loop_quick_cpu.json"),
    "loop.bench.paper": lambda r: bench_loop(r, "bench_loop_paper_gpu.json"),
    "loop.paper.effects": lambda r: loop_effects(r, "paper/loop_method/loop_real.csv"),
    "loop.paper.heldout": lambda r: loop_change(r, "mae_heldout_px", "px", 4, "paper/loop_method/loop_real.csv"),
    "loop.paper.mae_mm": lambda r: loop_change(r, "mae_mean_mm", "mm", 4, "paper/loop_method/loop_real.csv"),
    "loop.paper.target": lambda r: loop_target(r, "paper/loop_method/report.md"),
    "loop.paper.rest": lambda r: loop_rest_ratio(r, "paper/loop_method/report.md"),
    "loop.paper.method_same": lambda r: loop_same_table(r, "paper/loop/loop_real.csv",
                                                        "paper/loop_method/loop_real.csv"),
    "loop.quick.effects": lambda r: loop_effects(r, "quick/loop_real_method.csv"),
    "loop.quick.heldout": lambda r: loop_last(r, "mae_heldout_px", "px", 2, "quick/loop_real_method.csv"),
    # docs/twin.md
    "twin.cpu.speedup": lambda r: twin_cpu_auto(r, "speedup"),
    "twin.cpu.times": lambda r: twin_cpu_auto(r, "times"),
    "twin.streamed.core": twin_streamed_core,
    "twin.resident.times": twin_resident_times,
    # docs/twin.md, docs/loop.md, docs/calibration.md: workflow/scripts/twin_verification.py's record
    "twin.stable_dt": stable_dt_table,
    **{f"twin.stable_dt.{w}": (lambda r, w=w: stable_dt(r, w)) for w in ("margin", "physical_over", "damping", "coarse")},
    "twin.uniaxial": uniaxial_table,
    **{f"twin.verify.{w}": (lambda r, w=w: verification(r, w))
       for w in ("uniaxial", "energy_undamped", "energy_damped", "mass_scale", "mass_scale_prose")},
    "twin.binding": lambda r: binding_offset(r, "both"),
    "twin.binding.coarse": lambda r: binding_offset(r, "coarse"),
    # docs/recipe.md
    "train.stacked": train_stacked,
    "recipe.rows": recipe_rows,
    "recipe.robust_ap": lambda r: (f"Sim→Silicone AP {recipe_ap(r, 'A-to-B', 'robust')} (reference "
                                   f"{recipe_ap(r, 'A-to-B', 'reference')}), Sim→Meat "
                                   f"{recipe_ap(r, 'A-to-C', 'robust')} (reference "
                                   f"{recipe_ap(r, 'A-to-C', 'reference')})"),
    "recipe.pos_share": lambda r: (f"{recipe_pair(r, 'pos_share_05', 'robust', '{:.1%}')} (reference "
                                   f"{recipe_pair(r, 'pos_share_05', 'reference', '{:.1%}')})").replace("%", " %"),
    "recipe.ece_stored": lambda r: recipe_pair(r, "ece", "robust", "{:.3f}"),
    "recipe.ece_crossfit": recipe_crossfit_ece,
    "recipe.no_rotation": recipe_no_rotation,
    "recipe.c_to_b": lambda r: (f"robust {recipe_ap(r, 'C-to-B', 'robust')}; without early stopping "
                                f"{recipe_ap(r, 'C-to-B', 'robust', 'early_stop')}"),
    # docs/slides.md
    "slides.gate": slide_gate,
    **{f"slides.drift.{p}": (lambda r, p=p: drift_bound(r, p))
       for p in ("no_motion", "other_fold_drift", "same_lane_drift", "own_translation", "own_affine")},
    "twin_choice.slides": twin_choice_slides,
    "slides.static_offset": slide_static_offset,
    # docs/DEVELOPING.md: the reproducibility contract's measurement
    "contract.identical": lambda r: contract_identical(r, {"summary.csv": "data summary",
                                                           "calibration.csv": "calibration"}),
    "contract.loop_heldout": lambda r: contract_value(r, "loop_real.csv", "mae_heldout_px", "measured", 3, "px"),
    "contract.auroc": lambda r: contract_value(r, "seed_sweep.csv", "auroc", "measured", 4),
    "contract.ap": lambda r: contract_value(r, "seed_sweep.csv", "ap", "measured", 4),
    "contract.markers_auroc": lambda r: contract_value(r, "table4_markers.csv", "auroc", "measured", 4),
    "contract.maps_dbar": lambda r: contract_value(r, "table4_maps.csv", "d_bar_mm", "measured", 3, "mm"),
    "contract.tol.auroc": lambda r: contract_value(r, "seed_sweep.csv", "auroc", "tolerance", 2),
    "contract.tol.ap": lambda r: contract_value(r, "seed_sweep.csv", "ap", "tolerance", 2),
    "contract.tol.loop_heldout": lambda r: contract_value(r, "loop_real.csv", "mae_heldout_px", "tolerance", 2, "px"),
    "contract.tol.calibration": lambda r: contract_value(r, "calibration.csv", "fitted_px", "tolerance", 0),
    # docs/maps.md: the Silicone poses reconstructed and checked (silicone_pose_check.json)
    **{f"maps.silicone.{w}": (lambda r, w=w: silicone_check(r, w)) for w in SILICONE_MEASURES},
}
