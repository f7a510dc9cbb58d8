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
from palpation.model.config import ModelConfig
from palpation.model.stgnn import STGNN

FORMAT = "palpation-stgnn-1"


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
    """-> (model in eval mode, its normalisation statistics, rest layout (127, 2), payload)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"checkpoint {path} not found; train a model first (palpation.apps.train)")
    try:
        payload = torch.load(path, map_location=device, weights_only=False)
    except Exception as exc:  # torch raises RuntimeError, EOFError, UnpicklingError... for a damaged file
        raise ValueError(f"checkpoint {path} is damaged or truncated ({type(exc).__name__}); retrain it "
                         "(rerun its train rule)") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise ValueError(f"{path} is not a palpation ST-GNN checkpoint (format {found!r}); retrain it "
                         "(rerun its train rule)")
    model = STGNN(payload["clip_len"], ModelConfig(**payload["model_config"])).to(device)
    model.load_state_dict(payload["state_dict"])
    model.eval()
    return model, NormStats.from_dict(payload["norm_stats"]), np.asarray(payload["rest_px"]), payload
