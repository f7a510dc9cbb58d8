"""Where things live: the repository root, shipped reference data and generated results."""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
REFERENCE_DATA = REPO_ROOT / "data" / "reference"
FLAT_TIP_PHOTOS = REFERENCE_DATA / "photos" / "flat-tip"
VIDEOS = REFERENCE_DATA / "videos"
PHANTOM = REFERENCE_DATA / "phantom"


def results_dir() -> Path:
    """Root of generated outputs; `PALPATION_RESULTS` moves it (tests use a temp dir)."""
    return Path(os.environ.get("PALPATION_RESULTS", REPO_ROOT / "results"))
