"""The train_tables app on hand-made run folders: CSV columns, best-of-five, Markdown beside the paper, Fig. 6."""

import json

import pandas as pd
from hydra import compose, initialize_config_dir

from palpation.apps.train_tables import run
from palpation.paths import REPO_ROOT

CONFIGS = ["A-to-A", "A-to-B", "A-to-C", "C-to-B"]


def test_train_tables_and_figure(tmp_path, fake_run, results_tmp):
    root, out = tmp_path / "train", tmp_path / "report"
    for c in CONFIGS:
        for s in (0, 1):
            fake_run(root, c, 5, s)
    for clip_len in (1, 3):
        for s in (0, 1):
            fake_run(root, "A-to-B", clip_len, s)
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="train_tables", overrides=[
            f"runs_root={root}", f"out_dir={out}", "seeds=[0,1]", "profile=quick",
            "ablation.clip_lens=[1,3,5]", "ablation.seeds=[0,1]"])
    assert run(cfg) == {"runs": 8, "ablation_runs": 6}
    assert list((results_tmp / "mlartifacts" / "train_tables").rglob("fig6_pr_curves.png"))  # Fig. 6 in MLflow

    sweep = pd.read_csv(out / "seed_sweep.csv")
    assert list(sweep.columns) == ["config", "seed", "auroc", "ap", "fg_iou", "bg_iou", "mcc", "f1",
                                   "precision", "recall", "chance"]
    assert len(sweep) == 8
    t4 = pd.read_csv(out / "table4_markers.csv")
    for _, row in t4.iterrows():  # best-of-five = highest AP of the configuration
        assert row["ap"] == sweep[sweep.config == row["config"]]["ap"].max()
    abl = pd.read_csv(out / "clip_len_ablation.csv")
    assert list(abl.columns) == ["clip_len", "seed", "fg_iou", "ap"] and sorted(set(abl.clip_len)) == [1, 3, 5]
    md = (out / "table4_markers.md").read_text()
    assert "quick profile" in md and "Sim→Silicone (2), paper" in md and "| 909 |" in md
    assert "0.2384 ± 0.0012 (0.2371–0.2394)" in (out / "table3_clip_len.md").read_text()
    assert "0.958 ± 0.001" in (out / "seed_sweep.md").read_text()
    assert (out / "fig6_pr_curves.png").stat().st_size > 0 and (out / "fig6_pr_curves.pdf").exists()
    assert len(json.loads((out / "bench_train.json").read_text())["runs"]) == 12
