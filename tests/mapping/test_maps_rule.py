"""The `vessel_maps` rule in a scratch Snakefile beside the real rule files: a dry run wires the five
seeds of each mapped configuration and the test sets into the app."""

import os
import subprocess
import sys
from pathlib import Path

from palpation.paths import REPO_ROOT

RULES = ("common", "photos", "silicone", "meat", "twin", "simulate", "train", "maps")


def dry_run(tmp_path: Path, *args: str) -> str:
    work = tmp_path / "wd"
    work.mkdir()
    for name in ("workflow", "conf", "data"):
        os.symlink(REPO_ROOT / name, work / name)
    includes = "\n".join(f'include: "workflow/rules/{r}.smk"' for r in RULES)
    (work / "Snakefile").write_text(f"{includes}\n\n\nrule all:\n    input:\n        rules.vessel_maps.output,\n")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    out = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "2", "-n", "-p", *args], cwd=work,
                         env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert not (work / "results").exists(), "a dry run must not create outputs"
    return out.stdout


def test_vessel_maps_rule_takes_every_seed_and_the_test_sets(tmp_path):
    text = dry_run(tmp_path, "--config", "profile=paper", "maps={configs: [C-to-B]}")  # 5 seeds
    assert "rule vessel_maps:" in text
    for seed in range(5):
        assert f"results/train/C-to-B/L5/seed{seed}/scores.npz" in text
    assert "'configs=[C-to-B]'" in text and "data.silicone=results/data/silicone/silicone.npz" in text
    assert "results/maps/fig7_confusion_maps.pdf" in text and "results/maps/C-to-B_confusion_big.png" in text
