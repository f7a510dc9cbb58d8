"""Hydra entry point: the summary table of every real set (`out.csv` and `out.md`).

Every set listed under `datasets` must exist; a missing one fails the job, naming the file.
"""

from __future__ import annotations

import logging

import hydra
from omegaconf import DictConfig, OmegaConf

from palpation.config_check import app_main
from palpation.config_ranges import DictOf, Int, Num
from palpation.io import save_text
from palpation.realdata.summary import specs_from_mapping, summary_table, to_markdown

log = logging.getLogger(__name__)
RANGES = {"datasets": DictOf(min_len=1), "datasets.*.central_trim": Int(ge=0),  # checked before any work
          "datasets.*.reference_positive_rate": Num(ge=0, le=1, null=True)}


def run(cfg: DictConfig) -> dict:
    table = summary_table(specs_from_mapping(OmegaConf.to_container(cfg.datasets, resolve=True)))
    save_text(cfg.out.csv, table.to_csv(index=False, float_format="%.6f"))
    save_text(cfg.out.md, to_markdown(table))
    log.info("real data summary:\n%s", table.to_string(index=False))
    return {row["dataset"]: row for row in table.to_dict(orient="records")}


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="data_summary")
@app_main("data_summary", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
