"""workflow/scripts/gpu_recipe_ablation.sh at toy size on the CPU: one part of the ablation through Snakemake, the
seeds and the two Sim-trained configurations in one job, packed for the trip back from the device."""

import hashlib
import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest
import yaml

from palpation.graph.layout import rest_layout
from palpation.graph.sources import sim_trajectory_files
from palpation.graph.synthetic import write_meat, write_silicone, write_sim
from palpation.model.recipe import SWITCHES
from palpation.paths import REPO_ROOT

SCRIPT = REPO_ROOT / "workflow" / "scripts" / "gpu_recipe_ablation.sh"
TOY = {"train": {"seeds_together": True, "recipe_ablation": {
    "experiments": ["A-to-B", "A-to-C", "C-to-B"], "seeds": [0, 1], "switches": ["jitter"],
    "switch_experiments": ["A-to-B", "A-to-C"],
    "sizes": {"robust": {"large": {"batch_size": 2, "epochs": 2, "train_batches": 2, "val_batches": 1}}}}}}


def script(work: Path, out: str, *args: str, **env: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", "PROFILE": "tiny",
           "PALPATION_RESULTS": str(work / "results"), **env}
    return subprocess.run(["bash", str(SCRIPT), out, *args], cwd=work, env=env, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.slow  # Snakemake twice (~1 min on a loaded 2-core machine)
def test_a_part_runs_packs_and_resumes(tmp_path):
    work = tmp_path / "wd"
    work.mkdir()
    for name in ("Snakefile", "workflow", "conf", "data", "src"):
        os.symlink(REPO_ROOT / name, work / name)
    rest = rest_layout("template")  # the workflow's rest layout
    write_sim(work / "results/sim/dataset", rest, n_traj=7, n_frames=144)  # 2 clips of L=5 each
    (work / "results/data/silicone").mkdir(parents=True)
    (work / "results/data/meat").mkdir(parents=True)
    write_silicone(work / "results/data/silicone/silicone.npz", rest, n_videos=2, n_frames=8)
    write_meat(work / "results/data/meat/meat.npz", rest, n_frames=(9,) * 5, n_val=2)
    (work / "toy.yaml").write_text(yaml.safe_dump(TOY))
    # the datasets are given: only the ablation's rules may run (on the device the profile makes them)
    args = ["--configfile", "toy.yaml", "--allowed-rules", "train_recipe_seeds_sim_large", "recipe_robust_jitter"]

    bad = script(work, "out", *args, PART="robust_nope")
    assert bad.returncode == 2 and "PART 'robust_nope'" in bad.stderr
    first = script(work, "out_first", *args, "-n", PART=f"robust_{next(iter(SWITCHES))}")  # refused once: no prefix
    assert "is not all, reference_none" not in first.stderr, first.stderr
    # PART= (empty): the files given are the targets, here one configuration's row, not the whole row group's rule
    one = script(work, "out_one", *args, "-n", "results/recipe/robust/jitter/A-to-B/L5/seed0/metrics.json", PART="")
    plan = (work / "out_one/snakemake.log").read_text()
    assert one.returncode == 0 and "train_recipe_seeds_sim_large" in plan, (one.stderr + plan)[-2000:]
    assert "rule recipe_robust_jitter" not in plan  # (its name is in the echoed command line)
    done = script(work, "out", *args, PART="robust_jitter")
    assert done.returncode == 0, (done.stdout + (work / "out/snakemake.log").read_text())[-3000:]
    assert "4 finished runs" in done.stdout  # 2 seeds x (A-to-B, A-to-C), trained once
    sim = work / "results/sim/dataset"  # the fingerprint hashes the manifest's trajectory files, in its order
    names = [f.name for f in sim_trajectory_files(sim / "manifest.json")]
    lines = "".join(f"{hashlib.sha256((sim / n).read_bytes()).hexdigest()}  {n}\n" for n in names)
    assert (work / "out/sim_fingerprint.txt").read_text().strip() == hashlib.sha256(lines.encode()).hexdigest()[:16]
    with tarfile.open(work / "out/recipe_runs.tgz") as tar:
        names = sorted(tar.getnames())
    assert names == sorted(f"results/recipe/robust/jitter/{exp}/L5/seed{s}/{f}" for exp in ("A-to-B", "A-to-C")
                           for s in (0, 1) for f in ("metrics.json", "pr.npz", "scores.npz"))
    m = json.loads((work / "results/recipe/robust/jitter/A-to-C/L5/seed1/metrics.json").read_text())
    assert m["test_on"] == "meat" and m["trained_together"] == {**m["trained_together"], "seeds": [0, 1],
                                                                "configs": ["A-to-B", "A-to-C"]}
    assert "calibration" in m  # the robust recipe's Platt step ran; jitter was turned off (the part's switch)
    log = (work / "out/snakemake.log").read_text()
    assert "recipe.jitter_px=0.0" in log and "'also_test=[A-to-C:meat]'" in log
    again = script(work, "out", *args, PART="robust_jitter")  # a rerun keeps the finished job
    assert again.returncode == 0 and "Nothing to be done" in (work / "out/snakemake.log").read_text()


@pytest.mark.slow  # one Snakemake dry run (~15 s idle, ~60 s on a loaded 2-core machine)
def test_private_tree_with_the_carried_loop_plans_no_loop(tmp_path):
    """TREE + LOOP_FROM (a device shared with the judge's Snakemake): the run happens in a private copy, and the
    carried loop twin stands in for rule loop (and the carried photos and mesh for theirs), so the Sim set is rebuilt
    from that fit. A dry run (-n) shows the plan."""
    work = tmp_path / "wd"
    work.mkdir()
    for name in ("Snakefile", "workflow", "conf", "data", "src"):
        os.symlink(REPO_ROOT / name, work / name)
    for f in ("results/twin/mesh_coarse.npz", "results/twin/mesh_coarse.json",
              "results/data/photos/measured_photos.npz", "results/data/photos/measured_photos.json"):
        (work / f).parent.mkdir(parents=True, exist_ok=True)
        (work / f).write_text("carried")
    loop = tmp_path / "carried_loop"  # rule loop's outputs
    for f in ("report.md", "loop_real.csv", "rounds.json", "twin_fit/fitted.yaml", "fitted_params.yaml", "rounds.png",
              "rounds.pdf", "modes.png", "modes.pdf", "residuals/a.png", "tables/per_state.csv"):
        (loop / f).parent.mkdir(parents=True, exist_ok=True)
        (loop / f).write_text("fit")
    (work / "toy.yaml").write_text(yaml.safe_dump(TOY))
    tree = tmp_path / "tree"
    done = script(work, "out", "--configfile", "toy.yaml", "-n", PART="robust_jitter", TREE=str(tree),
                  LOOP_FROM=str(loop), GPU_SLOTS="5", PALPATION_RESULTS=str(tree / "results"))
    log = (work / "out/snakemake.log").read_text()
    assert done.returncode == 0, (done.stdout + done.stderr + log)[-3000:]
    assert "Sim set's twin: carried loop fit" in done.stdout
    jobs = {line.split()[0] for line in log.split("Job stats:")[1].split("total")[0].splitlines()[2:] if line.strip()}
    assert "simulate_dataset" in jobs and "train_recipe_seeds_sim_large" in jobs
    assert not jobs & {"loop", "measured_photos", "mesh"}, jobs
    assert (tree / "results/loop/twin_fit/fitted.yaml").read_text() == "fit" and not (work / "results/loop").exists()
