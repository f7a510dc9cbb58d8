"""The results page on a hand-made results tree: sections, the paper's numbers, differences, missing and
bad inputs, the atomic write, the app, and the rule in the DAG."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from palpation.apps.results_page import run
from palpation.paths import REPO_ROOT
from palpation.realdata.summary import REFERENCE_POSITIVE_RATE
from palpation.report import paper
from palpation.report.compare import Gap, Section
from palpation.report.results_page import Explanation, build_page, load_explanations, write_page

EXPLANATIONS = REPO_ROOT / "conf/results_page/explanations.yaml"
FOLDERS = REPO_ROOT / "conf/results_page/folders.yaml"
CONFIGS = ["A-to-A", "A-to-B", "A-to-C", "C-to-B"]


def csv(root: Path, rel: str, rows: list[dict]) -> None:
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).to_csv(path, index=False)


def sweep_rows(config: str, **metrics) -> list[dict]:
    base = dict(auroc=0.78, ap=0.30, fg_iou=0.2342, bg_iou=0.80, mcc=0.3, f1=0.39, precision=0.31, recall=0.53,
                chance=0.1133)
    spread = (-0.002, -0.001, 0.0, 0.001, 0.002)  # a seed spread around the means (verdicts need one)
    return [{"config": config, "seed": s, **base, **{m: base[m] + spread[s] for m in ("auroc", "ap", "fg_iou", "bg_iou")},
             **metrics} for s in range(5)]


def fake_results(root: Path) -> Path:
    """A results tree with every table the page reads, in the producers' columns, with known numbers."""
    csv(root, "data/summary.csv", [
        dict(dataset="silicone", trials=10, frames=160, markers_per_frame=127, positive_rate=0.1130,
             reference_positive_rate=0.1133),
        dict(dataset="meat", trials=10, frames=219, markers_per_frame=127, positive_rate=0.065077,
             reference_positive_rate=0.0651)])
    csv(root, "calibration/calibration.csv", [
        dict(interaction=i, undeformed_px=v["undeformed"] + 1.0, paper_params_px=v["twin"], fitted_px=v["twin"] + 1.0,
             fitted_mm=(v["twin"] + 1.0) * 2 / 55, used_for_fit=True) for i, v in paper.CALIBRATION_MAE.items()])
    csv(root, "loop/loop_real.csv", [
        dict(round=0, effect_added="none", residual_share_explained=None, mae_fit_px=14.0, mae_heldout_px=22.0,
             mae_mean_mm=0.6),
        dict(round=1, effect_added="surface_contact", residual_share_explained=0.6, mae_fit_px=5.5,
             mae_heldout_px=4.5, mae_mean_mm=0.2)])
    csv(root, "loop/tables/per_state.csv", [  # the loop's report tables as CSV, never parsed back from Markdown
        dict(state="press_d4", fit=True, baseline_px=14.29, round0_px=10.34, final_px=4.87, final_mm=0.177),
        dict(state="slide_d3", fit=False, baseline_px=14.54, round0_px=22.82, final_px=3.42, final_mm=0.124)])
    # A-to-B: AUROC 0.78 (paper 0.7789 ± 0.0043: within noise), AP 0.30 (paper 0.3213 ± 0.0043: 4.6σ lower)
    csv(root, "train/report/seed_sweep.csv", sum((sweep_rows(c) for c in CONFIGS), []))
    csv(root, "train/report/clip_len_ablation.csv",
        [dict(clip_len=L, seed=s, fg_iou=0.2384 if L == 5 else 0.10, ap=0.3243)
         for L in (1, 3, 5, 7) for s in (0, 1, 2)])
    csv(root, "train/report/table4_markers.csv", [
        dict(config=c, **{k: paper.TABLE4[c][k] for k in ("seed", "tp", "fp", "fn", "tn", "mcc", "f1", "precision",
                                                          "recall", "fg_iou", "bg_iou", "ap")}, auroc=0.8)
        for c in CONFIGS])
    csv(root, "maps/table4_maps.csv", [
        dict(config=c, **{**paper.TABLE4_MAPS[c], "d_bar_mm": paper.TABLE4_MAPS[c]["d_bar_mm"] + 0.5})
        for c in CONFIGS])
    csv(root, "maps/table4_maps_photo.csv", [
        dict(config="A-to-B/photo", **{**paper.TABLE4_MAPS["A-to-B"], "threshold": 0.61})])
    (root / "bench").mkdir()
    (root / "bench/reproduction.json").write_text(json.dumps([
        {"profile": "quick", "device": "cpu", "wall_s": 700.0, "per_rule": {"train": 300.0}, "commit": "aaa"},
        {"profile": "paper", "device": "cuda", "wall_s": 463.6, "per_rule": {"train": 1300.5, "loop": 78.1},
         "commit": "abc123"}]))
    (root / "calibration/fig4.png").write_bytes(b"png")
    return root


def page(root: Path, **kw) -> str:
    return build_page(root, EXPLANATIONS, FOLDERS, **kw)[0]


def test_full_page_puts_ours_beside_the_paper(tmp_path):
    text = page(fake_results(tmp_path / "results"), built_commit="abc123")
    assert "# Results beside the paper: paper profile" in text  # the latest record's profile
    assert "| device | cuda |" in text and "`abc123`" in text and "463.6 s" in text and "| train | 1300.5 |" in text
    for title in ("Data sets", "Calibration", "Residual loop", "Seed sweep", "Table 3", "Table 4, upper half",
                  "Table 4, lower half", "Figures", "Where and why they differ", "Folders"):
        assert f"## {title}" in text
    # data sets: the reference's counts and rates; 0.065077 rounds to the paper's 0.0651
    assert "| silicone | 10 | 10 | 160 | 160 | 0.1130 | 0.1133 | -0.0003, -0.3% |" in text
    assert "| meat | 10 | 10 | 219 | 219 | 0.0651 | 0.0651 | equal to 4 d.p. |" in text
    assert "| A-to-B | silicone | 15,240 | 15,240 | 1,727 | 1,727 | +0 |" in text  # TP + FN of Table 4
    assert "identical to the paper's in nodes and positives: A-to-A, A-to-B, A-to-C, C-to-B." in text
    # seed sweep: differences and their size in combined seed stds
    assert "| A-to-B | AUROC | 5 | 0.7800 ± 0.0016 | 0.7789 ± 0.0043 | +0.0011 | within seed noise (0.2σ) |" in text
    assert "| A-to-B | AP | 5 | 0.3000 ± 0.0016 | 0.3213 ± 0.0043 | -0.0213 | **4.6σ lower** |" in text
    assert "| A-to-A | AUROC | 5 | 0.7800 ± 0.0016 | 0.958 ± 0.001 |" in text  # A-to-A at the paper's 3 d.p.
    # Table 3 at L = 5 matches the paper's FG IoU; the best clip length is reported
    assert ("| 5 | FG IoU | 3 | 0.2384 ± 0.0000 (0.2384–0.2384) | 0.2384 ± 0.0012 (0.2371–0.2394) | +0.0000 |"
            in text)
    assert "Best mean FG IoU: ours at L = 5, the same as the paper's L = 5." in text
    # calibration: every fitted MAE 1 px above the paper's twin, margins equal
    assert ("| **mean** |  | 15.94 | 13.66 | **14.66 (0.53 mm)** | +1.28 | 14.94 | **13.66 (0.50 mm)** | +1.28 | "
            "+1.00 |") in text
    # residual loop: no paper loop; compared with the paper twin's 13.66 px
    assert "vs 0.497 mm (13.66 px)" in text and "| press_d4 | yes | 14.29 | 10.34 | 4.87 | 11.87 | -7.00 |" in text
    # Table 4 upper half equal to the paper; the maps' d-bar 0.5 mm above it
    assert "A-to-C (Sim→Meat): the best instance is the same seed as the paper's seed 2" in text
    assert "d̄ 1.55 vs 1.05 mm (+0.50), the same threshold rule" in text
    assert "| A-to-B (Sim→Silicone) | 0.6100 precision>=0.9@3mm | 0.5990 |" in text
    # missing optional table; figures that exist, linked relative to the page
    assert "*Not produced by this run*: `train/report/twin_ablation.csv` is missing" in text
    assert "[Fig. 4: fitted twin vs the photos](calibration/fig4.png)" in text and "fig6_pr_curves" not in text
    # explanations: only for tables on the page and conditions met
    assert "C-to-B: the reference recipe" in text and "Silicone poses are reconstructed" in text
    assert "FG/BG IoU below the paper's" not in text  # our IoUs are not below the paper's here
    assert "Quick profile:" not in text


def test_page_from_a_partial_run_says_what_is_missing(tmp_path):
    root = tmp_path / "results"
    csv(root, "data/summary.csv", [dict(dataset="silicone", trials=10, frames=160, markers_per_frame=127,
                                        positive_rate=0.1133, reference_positive_rate=0.1133)])
    text = page(root, profile="quick")
    assert "# Results beside the paper: quick profile" in text and "No timing record for this profile" in text
    for rel, rule in (("calibration/calibration.csv", "calibrate"), ("loop/loop_real.csv", "loop"),
                      ("train/report/seed_sweep.csv", "train_report"), ("maps/table4_maps.csv", "vessel_maps")):
        assert f"*Not produced by this run*: `{rel}` is missing (rule `{rule}` makes it)." in text
    assert "No figures produced by this run." in text
    assert "Quick profile: coarse mesh" in text  # the run-level explanation for this profile
    assert "### Data sets" in text and "### Seed sweep" not in text and "C-to-B: the reference" not in text


def test_missing_column_names_the_file_and_the_column(tmp_path):
    root = fake_results(tmp_path / "results")
    sweep = pd.read_csv(root / "train/report/seed_sweep.csv").drop(columns=["ap"])
    sweep.to_csv(root / "train/report/seed_sweep.csv", index=False)
    with pytest.raises(ValueError, match=r"seed_sweep\.csv: missing column\(s\) \['ap'\].*train_report"):
        page(root)


def test_twin_ablation_is_rendered_when_present(tmp_path):
    root = fake_results(tmp_path / "results")
    csv(root, "train/report/twin_ablation.csv", [
        dict(dataset_twin=t, experiment="A-to-B", n_seeds=5, auroc_mean=a, auroc_std=0.004, ap_mean=0.32,
             ap_std=0.004, fg_iou_mean=0.23, bg_iou_mean=0.8) for t, a in (("loop", 0.79), ("calibrated", 0.77))])
    text = page(root)
    assert "## Twin ablation" in text and "| A-to-B (Sim→Silicone) | calibrated | 5 | 0.7700 ± 0.0040 |" in text
    assert "| A-to-B (Sim→Silicone) | loop − calibrated |  | +0.0200 (**3.5σ higher**) | +0.0000" in text
    assert "only the twin that made the Sim set differs" in text


def test_explanation_conditions_and_bad_file(tmp_path):
    sec = Section("seed_sweep", "", "", [], [Gap("A-to-B", "bg_iou", -0.7, False), Gap("A-to-A", "ap", -0.1, True)],
                  {"A-to-A", "A-to-B"})
    assert Explanation("x", {"metrics": ["bg_iou"], "direction": "below"}).applies(sec, "paper")
    assert not Explanation("x", {"metrics": ["bg_iou"], "direction": "above"}).applies(sec, "paper")
    assert not Explanation("x", {"metrics": ["ap"]}).applies(sec, "paper")  # within noise
    assert not Explanation("x", {"configs": ["C-to-B"]}).applies(sec, "paper")
    assert not Explanation("x", {"profiles": ["quick"]}).applies(sec, "paper")
    bad = tmp_path / "e.yaml"
    bad.write_text("seed_swep:\n  - text: typo\n")
    with pytest.raises(ValueError, match=r"e\.yaml: unknown table key 'seed_swep'"):
        load_explanations(bad)
    bad.write_text("seed_sweep:\n  - text: x\n    when: {metric: [ap]}\n")
    with pytest.raises(ValueError, match=r"e\.yaml: seed_sweep\[0\]"):
        load_explanations(bad)
    assert set(load_explanations(EXPLANATIONS)) <= {"run", "data", "calibration", "loop", "seed_sweep", "table3",
                                                    "table4_markers", "table4_maps", "twin_ablation", "recipe_ablation",
                                                    "recipe_crossfit", "twin_selection", "transfer"}


def test_write_is_atomic(tmp_path, monkeypatch):
    out = tmp_path / "README.md"
    out.write_text("old page")
    real = Path.write_text

    def half_then_fail(self, text, *args, **kwargs):
        real(self, text[:5], *args, **kwargs)
        raise OSError("disk full")

    monkeypatch.setattr(Path, "write_text", half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        write_page(out, "a new page, much longer")
    monkeypatch.undo()
    assert out.read_text() == "old page"
    assert [p.name for p in tmp_path.iterdir()] == ["README.md"]  # no temp file left behind


def test_app_writes_the_page_and_links_relative_to_it(tmp_path, results_tmp):
    root = fake_results(tmp_path / "results")
    out = tmp_path / "docs" / "results.md"
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="results_page", overrides=[f"root={root}", f"out={out}"])
    result = run(cfg)
    assert result["out"] == str(out) and result["sections"]["seed_sweep"] and not result["sections"]["twin_ablation"]
    assert "[Fig. 4: fitted twin vs the photos](../results/calibration/fig4.png)" in out.read_text()
    assert not (root / "README.md").exists()  # the root is only read
    assert list((results_tmp / "mlartifacts" / "results_page").rglob("results.md"))  # the page is the run's artefact


def test_app_help():
    out = subprocess.run([sys.executable, "-m", "palpation.apps.results_page", "--help"], capture_output=True,
                         text=True, timeout=120, cwd=REPO_ROOT)
    assert out.returncode == 0 and "root=DIR" in out.stdout and "explanations=FILE" in out.stdout


def test_paper_numbers_have_one_home():
    from palpation.calibration.validate import SPEC_TWIN_PX
    from palpation.report import tables

    assert tables.TABLE4_MAPS is paper.TABLE4_MAPS and SPEC_TWIN_PX["press"] == 11.87
    for name, rate in REFERENCE_POSITIVE_RATE.items():
        assert paper.DATASETS[name]["positive_rate"] == rate
    assert round(sum(v["twin"] for v in paper.CALIBRATION_MAE.values()) / 4, 2) == paper.CALIBRATION_MEAN["twin"]


RULES = ("common", "photos", "silicone", "meat", "twin", "simulate", "calibrate", "loop", "dataset", "train", "maps",
         "recipe")


def dry_run(work: Path, snakefile: str | None, *args: str) -> str:
    """Dry-run in a scratch folder beside the checkout's workflow files (no results, no .snakemake)."""
    work.mkdir()
    for name in ("workflow", "conf", "data") + (("Snakefile",) if snakefile is None else ()):
        os.symlink(REPO_ROOT / name, work / name)
    if snakefile is not None:
        (work / "Snakefile").write_text(snakefile)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    out = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "2", "-n", "-p", *args], cwd=work, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert not (work / "results").exists(), "a dry run must not create outputs"
    return out.stdout


def test_results_page_is_in_the_dag(tmp_path):
    text = dry_run(tmp_path / "wd", None)
    assert "rule results_page:" in text and "output: results/README.md" in text
    assert "twin_ablation.csv" not in text.split("rule results_page:")[1].split("rule ")[0]


def test_twin_ablation_files_join_the_inputs_when_defined(tmp_path):
    includes = "\n".join(f'include: "workflow/rules/{r}.smk"' for r in RULES)
    snakefile = (f'{includes}\nTWIN_ABLATION_FILES = ["results/train/report/twin_ablation.csv"]\n\n\n'
                 'rule twin_ablation:\n    output:\n        TWIN_ABLATION_FILES,\n'
                 '    shell:\n        "touch {output}"\n\n\n'
                 'include: "workflow/rules/results_page.smk"\n')
    text = dry_run(tmp_path / "wd", snakefile, "results/README.md")
    job = text.split("rule results_page:")[1]
    assert "results/train/report/twin_ablation.csv" in job.split("output:")[0]
    assert "palpation.apps.results_page root=results out=results/README.md profile=quick" in text


def crossfit_rows() -> list[dict]:
    """A toy recipe_calibration_crossfit.csv: robust rows of the three configurations under each calibration."""
    base = dict(recipe="robust", switch_off="none", seeds=5, ece_std=0.001, brier=0.1, map_recall=0.8,
                map_pred_px=1000.0, map_threshold_from="test map (SPEC §12, quirk 18)", d_bar_05_mm=2.5,
                map_recall_05=0.6, d_bar_05_seeds=5)
    rows = []
    for config, ap, partner in (("A-to-B", 0.35, "meat (A-to-C scores)"), ("A-to-C", 0.31, "silicone (A-to-B scores)"),
                                ("C-to-B", 0.25, None)):
        for cal, ece, pos, fitted in (("stored", 0.2, 0.4, "sim_val"), ("cross_real", 0.07, 0.1, partner),
                                      ("cross_real_shift", 0.09, 0.1, partner), ("in_sample", 0.01, 0.0, "itself")):
            fitted = "meat_val" if partner is None and cal != "in_sample" else fitted
            cross = cal.startswith("cross") and partner is not None
            rows.append({**base, "config": config, "calibration": cal, "fitted_on": fitted, "ece": ece,
                         "pos_share_05": pos, "ap": ap, "d_bar_mm": 4.5 if cross else 3.5,
                         "map_pred_px": 3000.0 if cross else 1000.0,
                         "map_threshold_from": "other map (SPEC §12 rule)" if cross else base["map_threshold_from"]})
    rows.append({**rows[0], "switch_off": "calibration", "fitted_on": "none", "ece": 0.45, "pos_share_05": 0.7})
    return rows


def test_crossfit_section_says_by_how_much_each_aim_is_missed(tmp_path):
    root = fake_results(tmp_path / "results")
    assert ("*Not produced by this run*: `recipe/report/recipe_calibration_crossfit.csv` is missing (rule "
            "`recipe_crossfit` makes it).") in page(root)
    csv(root, "recipe/report/recipe_calibration_crossfit.csv", crossfit_rows())
    csv(root, "recipe/report/recipe_ablation.csv", [
        dict(config="C-to-B", recipe="robust", switch_off="none", seeds=5, auroc_mean=0.7, auroc_std=0.01,
             ap_mean=0.25, ap_std=0.05, pos_share_05=0.0, ece=0.02, d_bar_mm=2.0)])
    (root / "recipe/report/reliability_crossfit.png").write_bytes(b"png")
    text = page(root, links="results/paper")
    sec = text.split("## Training recipe: calibration cross-fitted")[1].split("\n## ")[0]
    assert "Not produced" not in sec
    assert "* A-to-B (Sim→Silicone): scores calibrated on meat (A-to-C scores); map threshold from other map" in sec
    assert "C-to-B (Meat→Silicone): scores calibrated on meat_val" in sec and "nothing to cross-fit" in sec
    assert "robust − `calibration`: the raw scores | none | 0.4500 ± 0.0010 | 70.0 % |" in sec
    assert "[reliability_crossfit.png](results/paper/recipe/report/reliability_crossfit.png)" in sec
    # every aim from the CSVs: AP 0.35 vs 0.40, ECE 0.07 vs 0.05, d-bar 4.5 vs 3 mm, AP std 0.05 vs 0.03
    assert "A-to-B (Sim→Silicone): AP 0.350 (aim >= 0.4): **missed by 0.050**; why: AP is the same" in sec
    assert "A-to-C (Sim→Meat): AP 0.310 (aim >= 0.3): met." in sec
    assert "C-to-B (Meat→Silicone): AP std over seeds 0.0500 (aim <= 0.03): **missed by 0.0200**" in sec
    assert "A-to-B (Sim→Silicone): positive at 0.5 10.0 % (aim <= 30 %): met." in sec
    assert "A-to-C (Sim→Meat): ECE 0.070 (aim <= 0.05): **missed by 0.020**; why: Platt fitted on the test set" in sec
    assert "C-to-B (Meat→Silicone): ECE 0.070 (aim <= 0.05): **missed by 0.020**" in sec
    assert ("A-to-C (Sim→Meat): d̄ at the other set's map threshold 4.50 mm (aim <= 3 mm): **missed by 1.50 mm**; "
            "why: the other set's threshold marks 3,000 pixels against 1,000") in sec
    assert "A-to-C (Sim→Meat): d̄ at calibrated 0.5 2.50 mm (aim <= 3 mm): met." in sec
    diff = text.split("### Training recipe: calibration cross-fitted")[1].split("\n### ")[0]
    assert "5 of 11 aim checks met, 6 missed" in diff and "want different Platt slopes" in diff


def test_data_section_names_the_twin_that_made_the_sim_set(tmp_path):
    root = fake_results(tmp_path / "results")
    assert "sim: simulated by" not in page(root)  # neither record: the page says nothing it cannot read
    log = root / "logs" / "sim" / "simulate_dataset.log"
    log.parent.mkdir(parents=True)
    log.write_text("Sim set twin: dataset.twin=photo_loop, fit results/loop/twin_fit/fitted.yaml\nWarp ...\n")
    assert ("sim: simulated by dataset.twin=photo_loop, fit results/loop/twin_fit/fitted.yaml "
            "(`logs/sim/simulate_dataset.log`).") in page(root)
    choice = root / "judge" / "choice" / "choice.json"  # rule twin_choice's record wins over the log
    choice.parent.mkdir(parents=True)
    choice.write_text(json.dumps({"sim_set_twin": "calibrated", "how": "the evidence's choice"}))
    assert "sim: simulated by the `calibrated` twin (the evidence's choice; `judge/choice/choice.json`)." in page(root)


def test_timing_record_of_the_same_commit_by_short_hash_is_not_stale(tmp_path):
    from palpation.report.results_page import timing

    rec = {"commit": "e80d176", "wall_s": 473.7, "per_rule": {"slide_loop": 273.7}}
    full = "e80d176f4d3c89857ee778c5a75d77c7b69570c0"
    assert not timing(tmp_path, rec, full)["stale"]
    assert not timing(tmp_path, {**rec, "commit": full}, full)["stale"]
    assert timing(tmp_path, {**rec, "commit": "9665dd9"}, full)["stale"]
    assert timing(tmp_path, {**rec, "commit": ""}, full)["stale"]  # no commit recorded: cannot be the page's


def test_transfer_section_checks_the_aims_on_the_cross_real_inductive_choice(tmp_path):
    root = fake_results(tmp_path / "results")
    assert "`transfer/transfer.csv` is missing" in page(root)
    row = dict(seeds=5, auroc_mean=0.75, pos_share_05=0.1)
    csv(root, "transfer/transfer.csv", [
        dict(config="A-to-B", method="m_real", selection="cross_real", transductive="false", chosen="true",
             ap_mean=0.31, ap_std=0.03, **row),
        dict(config="A-to-B", method="m_best", selection="cross_real", transductive="false", chosen="false",
             ap_mean=0.45, ap_std=0.01, **row),  # the best test score, not chosen: the aim ignores it
        dict(config="A-to-B", method="m_tr", selection="cross_real", transductive="true", chosen="true",
             ap_mean=0.50, ap_std=0.01, **row),  # transductive: reported apart, never toward the aim
        dict(config="A-to-C", method="m_real", selection="cross_real", transductive="false", chosen="true",
             ap_mean=0.33, ap_std=0.01, **row)])
    (root / "data" / "meat").mkdir(parents=True)
    (root / "data" / "meat" / "meat.json").write_text(json.dumps({"nodes": 1000, "ref_hard_positives": 250,
                                                                  "ref_hard_accuracy": 0.78}))
    text = page(root)
    sec = text.split("## Transfer beyond the paper")[1].split("\n## ")[0]
    assert "25.0 % of markers positive, accuracy 0.780" in sec
    assert f"| 0.3100 ± 0.0300 | 0.7500 | {paper.SEED_SWEEP['A-to-B']['ap'][0]:.4f} /" in sec
    diff = text.split("### Transfer beyond the paper")[1].split("\n### ")[0]
    assert "A-to-B m_real (cross_real, inductive): AP 0.31 (aim >= 0.4): **missed by 0.09**" in diff
    assert "A-to-B m_real (cross_real, inductive): AP std 0.03 (aim <= 0.02): **missed by 0.01**" in diff
    assert "A-to-C m_real (cross_real, inductive): AP 0.33 (aim >= 0.3): met." in diff
    assert "m_best" not in diff and "m_tr" not in diff
