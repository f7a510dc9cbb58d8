"""Scoring the dedicated Sim map slide with a trained checkpoint (SPEC §8.3 "Sim vessel map").

The Sim test split has only 9 windows per slide (starts every 24 frames). For the map of one
vessel-present slide the reference scores every start s = 0 .. n - 24 L with the same dilation 24,
so the central frames step by one recorded frame (~0.12 mm).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from palpation.graph.clips import ClipSet
from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.sources import SIM_STRIDE, load_sim


def dense_windows(lengths, clip_len: int, stride: int = SIM_STRIDE) -> np.ndarray:
    """(N, 2) sequence index and start for every start s = 0 .. n - stride * L of each sequence."""
    rows = [(i, s) for i, n in enumerate(lengths) for s in range(max(int(n) - stride * clip_len + 1, 0))]
    if not rows:
        raise ValueError(f"no dense window of {clip_len} frames at dilation {stride} fits in sequences of "
                         f"{sorted(set(int(n) for n in lengths))} frames")
    return np.array(rows, np.int64)


def score_dense(checkpoint: str | Path, manifest: str | Path, split: str = "all", batch_size: int = 64,
                device: str = "cpu", progress: bool = False) -> dict:
    """Central-frame probs/labels of every dense window of the slides in `manifest`, and their
    (sequence, frame) ids; sequences in sorted-name order as in palpation.mapping.sources.sim_source.
    `progress`: a tqdm bar over the scoring batches."""
    from palpation.model.checkpoint import load_checkpoint
    from palpation.model.evaluate import predict

    model, stats, rest, payload = load_checkpoint(checkpoint, device)
    clip_len = int(payload["clip_len"])
    seqs = load_sim(manifest, split)
    clips = ClipSet(seqs, clip_len, rest)
    clips.windows = dense_windows([len(m) for m in seqs.markers], clip_len, seqs.stride)
    topo = clip_topology(spatial_edges(rest), clip_len)
    probs, labels = predict(model, clips, stats, rest, topo, batch_size, device=device, progress=progress)
    sequence, frame = clips.central_frames()
    return {"probs": probs, "labels": labels, "sequence": sequence, "frame": frame, "clip_len": clip_len,
            "ids": list(seqs.ids)}
