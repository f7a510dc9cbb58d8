"""Hydra entry point: the results page, every table of a run beside the paper's numbers.

    python -m palpation.apps.results_page                                   results/ -> results/README.md
    python -m palpation.apps.results_page root=/data/results out=/tmp/page.md profile=paper
    python -m palpation.apps.results_page --help
Reads the outputs under `root` (never writes there unless `out` points there) and writes one Markdown page.
"""

from __future__ import annotations

import logging
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from palpation.config_check import app_main
from palpation.config_ranges import Num
from palpation.paths import REPO_ROOT
from palpation.report.results_page import build_page, write_page
from palpation.tracking import git_commit

log = logging.getLogger(__name__)
RANGES = {"noise_k": Num(gt=0)}  # checked before any work (config_ranges)


def conf_file(path: str) -> Path:
    """A data file given relative to the working directory, else to the repository (the app runs anywhere)."""
    p = Path(path)
    if p.is_absolute() or p.exists():
        return p
    if (REPO_ROOT / p).exists():
        return REPO_ROOT / p
    raise FileNotFoundError(f"{path} not found (neither in {Path.cwd()} nor in {REPO_ROOT})")


def run(cfg: DictConfig) -> dict:
    c = OmegaConf.to_container(cfg, resolve=True)
    c.pop("hydra", None)
    out = Path(c["out"])
    text, secs = build_page(c["root"], conf_file(c["explanations"]), conf_file(c["folders"]), profile=c["profile"],
                            page_dir=out.parent, links=c["links"], k=float(c["noise_k"]), built_commit=git_commit())
    write_page(out, text)
    present = {k: v is not None for k, v in secs.items()}
    log.info("results page %s from %s: %s", out, c["root"], present)
    if c["track"]:
        from palpation import tracking

        with tracking.start_run("results_page", {k: c[k] for k in ("root", "out", "profile", "noise_k")}):
            tracking.log_metrics({"sections_present": sum(present.values())})
            tracking.log_artifact(out)
    return {"out": str(out), "sections": present}


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="results_page")
@app_main("results_page", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
