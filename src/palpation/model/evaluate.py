"""Scoring clips with a trained model: central-frame probabilities and labels (SPEC §10, §11)."""

from __future__ import annotations

import numpy as np
import torch

from palpation.graph.batch import make_batch
from palpation.graph.clips import ClipSet, central_offset
from palpation.graph.edges import ClipTopology
from palpation.graph.features import ClipFeatures, clip_features
from palpation.graph.normalise import NormStats
from palpation.markers.lattice import N_MARKERS
from palpation.progress import bar


def central_slice(clip_len: int) -> slice:
    """Marker nodes of the central frame inside one clip."""
    k = central_offset(clip_len)
    return slice(k * N_MARKERS, (k + 1) * N_MARKERS)


def aligned_features(align, clips: ClipSet, idx: np.ndarray, markers: np.ndarray, rest: np.ndarray,
                     topo: ClipTopology, remove_common_motion: bool) -> ClipFeatures:
    """The raw features of clips `idx` (their `markers`) with `align` applied by each clip's sequence."""
    return align.apply(clip_features(markers, rest, topo, remove_common_motion), clips.windows[idx, 0])


@torch.no_grad()
def predict(model: torch.nn.Module, clips: ClipSet, stats: NormStats, rest: np.ndarray,
            topo: ClipTopology, batch_size: int, max_batches: int | None = None,
            device: str = "cpu", progress: bool = False, align=None) -> tuple[np.ndarray, np.ndarray]:
    """Central-frame (probs float32, labels int8), pooled in clip order; no augmentation.

    `progress`: a tqdm bar over the batches (test scoring; the per-epoch validation leaves it off). `align`: a
    graph.align.Alignment applied to the clips' raw features before the statistics (test scoring only)."""
    model.eval()
    n = len(clips) if max_batches is None else min(len(clips), max_batches * batch_size)
    probs, labels = [], []
    centre = central_slice(topo.clip_len)
    for start in bar(range(0, n, batch_size), desc="score", unit="batch", enabled=progress):
        idx = np.arange(start, min(start + batch_size, n))
        markers, lab = clips.gather(idx)
        feats = None if align is None else aligned_features(align, clips, idx, markers, rest, topo,
                                                              stats.remove_common_motion)
        batch = make_batch(markers, lab, rest, topo, stats, device, features=feats)
        p = torch.sigmoid(model(batch)).view(len(idx), topo.n_markers)[:, centre]
        probs.append(p.cpu().numpy().ravel())
        labels.append(lab.reshape(len(idx), -1)[:, centre].ravel())
    return np.concatenate(probs).astype(np.float32), np.concatenate(labels).astype(np.int8)
