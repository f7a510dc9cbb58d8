# Shared settings: the active profile's workflow config and helpers for calling Hydra apps.
import sys

import yaml
from pathlib import Path

from palpation.confdeps import conf_files

PROFILE = config.get("profile", "quick")
_profile_file = Path("conf/workflow") / f"{PROFILE}.yaml"
if not _profile_file.exists():
    raise ValueError(f"unknown profile '{PROFILE}': {_profile_file} does not exist")
for _key, _value in yaml.safe_load(_profile_file.read_text()).items():
    config.setdefault(_key, _value)  # command-line --config wins

PY = f"{sys.executable} -m"  # the interpreter running Snakemake (venv or GPU node)
REF = "data/reference"
PHOTOS = f"{REF}/photos/flat-tip"
VIDEOS = f"{REF}/videos"


def hydra_dir(path):
    """Pin Hydra's run folder next to a rule's output so .hydra/config.yaml stays with it."""
    return f"hydra.run.dir={Path(path).parent} hydra.output_subdir=.hydra/{Path(path).stem}"

# Every job knows its profile (MLflow tags runs with it) and writes no MLflow artefacts into ./mlruns.
# The prefix is formatted once, not per job, so each shell command starts with `SNAKEMAKE_RULE={rule}`
# itself: MLflow tags every run with its rule (palpation.tracking, the job key of a rerun).
# Hydra rules declare the conf/ files their app composes (conf_files) so that an edit reruns exactly them.
shell.prefix(f"set -euo pipefail; export PALPATION_PROFILE={PROFILE}; ")
