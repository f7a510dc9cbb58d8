"""Reuse an earlier judge run's candidates (issue 12; docs/slides.md "Paper-profile run"): a candidate twin's
fitted twin and its trained runs, copied so that a later run (config `judge.reuse`) reruns only what changed.

The fitted twin is the one the earlier run replayed: the `twin` section of its judge_slides job's composed
config (results/judge/slides/.hydra/<twin>/config.yaml), written as a twin option (twin_fit/fitted.yaml,
package twin), so the replay uses exactly the twin whose Sim set trained the reused models. The runs keep the
layout <root>/<experiment>/L<n>/seed<s>/ with scores.npz and metrics.json (checkpoints and PR curves are left out).

    python -m palpation.judge.reuse SRC_RESULTS DEST calibrated photo_loop
    # then: gpu_judge.sh OUTDIR --configfile workflow/profiles/paper/judge_reuse.yaml (DEST = results/judge_reuse)

A developer tool outside the results DAG: argparse, like judge.budget.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import yaml

from palpation.io import save_json, save_text
from palpation.readers import read_yaml

KEPT = ("scores.npz", "metrics.json")


def reuse(src: str | Path, dest: str | Path, twin: str) -> dict:
    src, dest = Path(src), Path(dest)
    config = src / "judge" / "slides" / ".hydra" / twin / "config.yaml"
    runs = src / "judge" / "train" / twin
    for path in (config, runs):
        if not path.exists():
            raise ValueError(f"judge_reuse: {path} missing: SRC must be an earlier judge run's results folder "
                             f"(rule judge_slides and judge_train_seeds outputs for {twin})")
    composed = read_yaml(config, "rerun rule judge_slides in SRC (or pass another earlier judge run)",
                         "judge_reuse: composed config")
    if "twin" not in composed:
        raise ValueError(f"judge_reuse: {config} has no `twin` section; is it a task=slides config?")
    fit = dest / "twins" / twin / "twin_fit" / "fitted.yaml"
    save_text(fit, f"# @package twin\n# {twin}: the twin an earlier judge run replayed and trained on, from {config}\n"
              + yaml.safe_dump(composed["twin"], sort_keys=True))
    copied = []
    for f in sorted(runs.glob("*/L*/seed*/*")):
        if f.name in KEPT:
            out = dest / "train" / twin / f.relative_to(runs)
            out.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(f, out)
            copied.append(str(f.relative_to(runs)))
    if not any(c.endswith("scores.npz") for c in copied):
        raise ValueError(f"judge_reuse: no scores.npz under {runs}/<experiment>/L<n>/seed<s>/")
    return {"fit": str(fit), "runs": str(dest / "train" / twin), "files": copied}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("src", help="an earlier run's results folder (holding judge/slides and judge/train)")
    p.add_argument("dest", help="where to write them (results/judge_reuse for workflow/profiles/paper/judge_reuse.yaml)")
    p.add_argument("twins", nargs="+")
    a = p.parse_args()
    out = {t: reuse(a.src, a.dest, t) for t in a.twins}
    save_json(Path(a.dest) / "reuse.json", {"source": str(Path(a.src).resolve()), "twins": out})
    for t, r in out.items():
        print(f"{t}: {r['fit']} and {len(r['files'])} run files under {r['runs']}")


if __name__ == "__main__":
    main()
