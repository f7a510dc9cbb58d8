"""Checkpoints: weights together with everything needed to score new data the same way.

The normalisation statistics travel with the weights and are always loaded with them, so a test
domain is normalised by its training domain's statistics (SPEC §8.3).
"""

from __future__ import annotations

import dataclasses
import io
import os
from pathlib import Path

import numpy as np
import torch

from palpation.graph.normalise import NormStats
from palpation.io import save_bytes
from palpation.markers.lattice import N_MARKERS
from palpation.model.config import ModelConfig
from palpation.model.stgnn import STGNN
from palpation.readers import one_line, read_torch

FORMAT = "palpation-stgnn-1"
_PARTS = ("state_dict", "model_config", "clip_len", "norm_stats", "rest_px")


def save_checkpoint(path: str | os.PathLike, model: STGNN, model_cfg: ModelConfig, stats: NormStats,
                    rest: np.ndarray, extra: dict | None = None) -> None:
    payload = {
        "format": FORMAT,
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "model_config": dataclasses.asdict(model_cfg),
        "clip_len": model.clip_len,
        "norm_stats": stats.to_dict(),
        "rest_px": np.asarray(rest, np.float64).tolist(),
        "extra": extra or {},
    }
    # through memory: given a path, torch.save names the zip's folder after the file, and the atomic
    # write's temporary name would make every checkpoint differ; a buffer's folder is always "archive"
    buf = io.BytesIO()
    torch.save(payload, buf)
    save_bytes(path, buf.getvalue())


def checkpoint_bytes(model: STGNN) -> int:
    """Size of the weights as torch.save writes them (~4.2 MB large, ~300 KB compact)."""
    buf = io.BytesIO()
    torch.save(model.state_dict(), buf)
    return buf.tell()


def load_checkpoint(path: str | os.PathLike, device: str = "cpu") -> tuple[STGNN, NormStats, np.ndarray, dict]:
    """-> (model in eval mode, its normalisation statistics, rest layout (127, 2), payload).

    Read with weights_only (readers.read_torch: tensors and plain values, no code runs); a payload of another
    format, with missing parts or with weights that do not fit its model config is refused naming the file."""
    path = Path(path)
    fix = "retrain it (rerun its train rule, palpation.apps.train)"
    payload = read_torch(path, fix, "checkpoint", device)
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise ValueError(f"{path} is not a palpation ST-GNN checkpoint (format {found!r}); {fix}")
    missing = [k for k in _PARTS if k not in payload]
    if missing:
        raise ValueError(f"checkpoint {path} lacks {missing}; {fix}")
    try:
        model = STGNN(payload["clip_len"], ModelConfig(**payload["model_config"])).to(device)
        model.load_state_dict(payload["state_dict"])
        stats, rest = NormStats.from_dict(payload["norm_stats"]), np.asarray(payload["rest_px"], np.float64)
    except Exception as exc:  # noqa: BLE001  TypeError (config fields), RuntimeError (weight shapes), ...
        raise ValueError(f"checkpoint {path} does not fit its model ({one_line(exc)}); {fix}") from None
    if rest.shape != (N_MARKERS, 2) or not np.isfinite(rest).all():
        raise ValueError(f"checkpoint {path}: rest layout of shape {rest.shape} (or not finite), expected "
                         f"({N_MARKERS}, 2); {fix}")
    model.eval()
    return model, stats, rest, payload
