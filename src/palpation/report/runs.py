"""Finding and reading the outputs of training runs: `<root>/<config>/L<clip_len>/seed<seed>/`."""

from __future__ import annotations

from pathlib import Path

from palpation.readers import read_json

SWEEP_COLUMNS = ("config", "seed", "auroc", "ap", "fg_iou", "bg_iou", "mcc", "f1", "precision", "recall", "chance")


def run_dir(root: str | Path, config: str, clip_len: int, seed: int) -> Path:
    """The one place the run layout is spelled out (Snakemake's train rule writes the same)."""
    return Path(root) / config / f"L{clip_len}" / f"seed{seed}"


def load_runs(root: str | Path, configs, clip_lens, seeds) -> list[dict]:
    """metrics.json of every (config, clip_len, seed); missing runs raise one error naming them all."""
    runs, missing = [], []
    for config in configs:
        for clip_len in clip_lens:
            for seed in seeds:
                path = run_dir(root, config, clip_len, seed) / "metrics.json"
                if not path.exists():
                    missing.append(str(path))
                    continue
                m = read_json(path, "rerun the train rule for this run")
                runs.append({"config": config, "clip_len": clip_len, "seed": seed, "dir": str(path.parent),
                             **m["test"], "train_seconds": m.get("train_seconds"), "device": m.get("device")})
    if missing:
        raise FileNotFoundError(f"{len(missing)} training run(s) missing, e.g. {missing[:3]}; run the "
                                "train rule (snakemake) or palpation.apps.train for them first")
    return runs



def recipe_root(root: str | Path, recipe: str, switch_off: str) -> Path:
    """Runs of the recipe ablation (issue 15): <root>/<recipe>/<switch_off>/, then the run_dir layout."""
    return Path(root) / recipe / switch_off
