"""Hand-made training-run folders for the report apps."""

import zlib

import numpy as np
import pytest

from palpation.io import save_json
from palpation.metrics.classification import marker_metrics
from palpation.metrics.scores import Scores, save_scores
from palpation.report.runs import run_dir


def _fake_run(root, config, clip_len, seed):
    """metrics.json + scores.npz of one run (4 clips x 127 markers), scores differing per (config, clip_len, seed)."""
    rng = np.random.default_rng(zlib.crc32(f"{config}{clip_len}{seed}".encode()))
    labels = (rng.random(4 * 127) < 0.1).astype(np.int8)
    probs = np.clip(0.3 * labels + rng.random(4 * 127) * (0.5 + 0.1 * seed), 0, 1).astype(np.float32)
    out = run_dir(root, config, clip_len, seed)
    save_scores(out / "scores.npz", Scores(probs, labels, np.zeros(4, np.int64), np.arange(2, 6)))
    save_json(out / "metrics.json", {"test": marker_metrics(probs, labels), "train_seconds": 1.5,
                                     "device": "cpu"})


@pytest.fixture
def fake_run():
    return _fake_run
