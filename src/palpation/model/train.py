"""Training one ST-GNN (SPEC §10): focal loss with deep supervision, Adam, best-val checkpointing.

Randomness: one `numpy.random.default_rng(seed)` stream draws the normalisation clips, the epoch
orders and the rotations; torch's seed covers initialisation and dropout. On the CPU the same seed
gives bit-identical weights and metrics.
"""

from __future__ import annotations

import copy
import logging
import os
import random
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch
from sklearn.metrics import average_precision_score

from palpation.graph.augment import draw_displacement_scales, draw_rotations, drop_markers, jitter_markers
from palpation.graph.batch import make_batch
from palpation.graph.clips import ClipSet
from palpation.graph.edges import ClipTopology
from palpation.graph.features import clip_features
from palpation.graph.normalise import NormStats
from palpation.graph.pseudo import PSEUDO
from palpation.metrics.classification import confusion, iou
from palpation.model.config import ModelConfig, TrainConfig
from palpation.model.evaluate import predict
from palpation.model.stgnn import STGNN
from palpation.progress import bar

log = logging.getLogger(__name__)
NORM_CHUNK = 64  # clips per feature chunk when accumulating `full` statistics


def seed_everything(seed: int) -> None:
    """Seed Python, NumPy (legacy global, for third-party code), torch and CUDA; deterministic kernels."""
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    random.seed(seed)
    np.random.seed(seed % 2 ** 32)
    torch.manual_seed(seed)
    torch.cuda.manual_seed_all(seed)
    torch.backends.cudnn.deterministic = True
    torch.backends.cudnn.benchmark = False
    torch.use_deterministic_algorithms(True, warn_only=True)


def focal_loss(logits: torch.Tensor, targets: torch.Tensor, alpha: float, gamma: float) -> torch.Tensor:
    """FL = α_t (1 - p_t)^γ · BCEWithLogits, mean over nodes; α_t = α for positives, 1 - α for negatives."""
    bce = torch.nn.functional.binary_cross_entropy_with_logits(logits, targets, reduction="none")
    p = torch.sigmoid(logits)
    p_t = p * targets + (1 - p) * (1 - targets)
    alpha_t = alpha * targets + (1 - alpha) * (1 - targets)
    return (alpha_t * (1 - p_t) ** gamma * bce).mean()


def masked_focal_loss(logits: torch.Tensor, targets: torch.Tensor, weight: torch.Tensor, alpha,
                      gamma: float) -> torch.Tensor:
    """The focal loss of each node weighted, summed over the nodes of nonzero weight and divided by their count: a
    node of weight 0 adds nothing, whatever its target (its term is 0 and so is its gradient)."""
    bce = torch.nn.functional.binary_cross_entropy_with_logits(logits, targets, reduction="none")
    p = torch.sigmoid(logits)
    p_t = p * targets + (1 - p) * (1 - targets)
    alpha_t = alpha * targets + (1 - alpha) * (1 - targets)
    return (weight * alpha_t * (1 - p_t) ** gamma * bce).sum() / (weight > 0).sum().clamp(min=1)


def coded_targets(codes: torch.Tensor, pseudo_weight: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Targets and weights of label codes (graph.pseudo): a label weighs 1, a pseudo-label `pseudo_weight`, a
    marker without one 0 (its target set to 0, never read)."""
    pseudo = codes >= PSEUDO
    targets = torch.where(pseudo, codes - PSEUDO, codes).clamp(min=0)
    weight = torch.where(codes < 0, 0.0, torch.where(pseudo, pseudo_weight, 1.0))
    return targets, weight


def pseudo_focal_loss(logits: torch.Tensor, codes: torch.Tensor, alpha, gamma: float,
                      pseudo_weight: float) -> torch.Tensor:
    """The training loss of a set with pseudo-labels (recipe.pseudo): masked_focal_loss of the codes."""
    return masked_focal_loss(logits, *coded_targets(codes, pseudo_weight), alpha, gamma)


def train_step(model: torch.nn.Module, opt: torch.optim.Optimizer, batch, alpha: float,
               gamma: float, pseudo_weight: float | None = None) -> torch.Tensor:
    """One optimisation step of `fit`: focal loss over every frame's marker nodes, backward, Adam; the loss.
    `pseudo_weight`: the batch's `y` holds label codes (recipe.pseudo on): the masked loss of pseudo_focal_loss."""
    logits = model(batch)
    loss = focal_loss(logits, batch.y, alpha, gamma) if pseudo_weight is None \
        else pseudo_focal_loss(logits, batch.y, alpha, gamma, pseudo_weight)
    opt.zero_grad()
    loss.backward()
    opt.step()
    return loss


def pseudo_weight(cfg: TrainConfig) -> float | None:
    """The pseudo-labels' loss weight when self-training is on, else None (the plain focal loss)."""
    return None if cfg.pseudo == "none" else cfg.pseudo_weight


def grouped_parameters(named, weight_decay: float) -> list[dict]:
    """Weight decay on everything except parameters whose name contains 'bias' or 'bn'."""
    decay, no_decay = [], []
    for name, p in named:
        (no_decay if ("bias" in name or "bn" in name) else decay).append(p)
    return [{"params": decay, "weight_decay": weight_decay}, {"params": no_decay, "weight_decay": 0.0}]


def param_groups(model: torch.nn.Module, weight_decay: float) -> list[dict]:
    return grouped_parameters(model.named_parameters(), weight_decay)


def norm_stats(train: ClipSet, rest: np.ndarray, topo: ClipTopology, cfg: TrainConfig,
               rng: np.random.Generator) -> NormStats:
    """Statistics and α from augmented training clips: one batch of them (`sample`, quirk 7) or all (`full`)."""
    if cfg.norm_stats == "sample":
        n = cfg.norm_clips or cfg.batch_size
        idx = rng.choice(len(train), size=min(n, len(train)), replace=False)
    else:
        idx = np.arange(len(train))
    rot = draw_rotations(rng, len(idx), cfg.rotation)

    def chunks():
        for s in range(0, len(idx), NORM_CHUNK):
            m, lab = train.gather(idx[s:s + NORM_CHUNK], rot[s:s + NORM_CHUNK], cfg.rotation == "consistent",
                                  lattice=cfg.rotation == "lattice")
            yield clip_features(m, rest, topo, cfg.remove_common_motion), lab

    return NormStats.from_chunks(chunks(), cfg.norm_stats, cfg.remove_common_motion)


def val_fg_iou(probs: np.ndarray, labels: np.ndarray, threshold: float) -> float:
    return iou(probs >= threshold, labels.astype(bool))


def val_score(probs: np.ndarray, labels: np.ndarray, cfg: TrainConfig) -> float:
    """The checkpoint score: val FG IoU at the threshold (reference) or AP (0 without positives)."""
    if cfg.select_metric == "fg_iou":
        return val_fg_iou(probs, labels, cfg.threshold)
    return float(average_precision_score(labels, probs)) if labels.any() else 0.0


def epoch_row(epoch: int, losses: list, probs: np.ndarray, labels: np.ndarray,
              cfg: TrainConfig) -> tuple[dict, float]:
    """The end-of-epoch history row (train loss, val FG IoU/TP/FP and the selection metric) and the score that
    selects the checkpoint; `fit` and `stacked.fit_seeds` log the same row."""
    score = val_score(probs, labels, cfg)
    c = confusion(probs, labels, cfg.threshold)
    row = {"epoch": epoch, "train/loss": float(np.mean(losses)),
           "val/fg_iou": val_fg_iou(probs, labels, cfg.threshold), "val/tp": c["tp"], "val/fp": c["fp"]}
    if cfg.select_metric != "fg_iou":
        row[f"val/{cfg.select_metric}"] = score
    return row, score


def training_batch(train: ClipSet, idx: np.ndarray, cfg: TrainConfig, rng: np.random.Generator):
    """Markers and labels of one augmented training batch. Draw order: rotations (the reference's only
    draw), then only the switches that are on, so the reference stream is untouched."""
    rot = draw_rotations(rng, len(idx), cfg.rotation)
    scales = draw_displacement_scales(rng, len(idx), cfg.displacement_scale)
    m, lab = train.gather(idx, rot, cfg.rotation == "consistent", scales, lattice=cfg.rotation == "lattice")
    m = drop_markers(jitter_markers(m, rng, cfg.jitter_px), rng, cfg.marker_dropout)
    return m, lab


@dataclass
class FitResult:
    model: STGNN
    stats: NormStats
    best_epoch: int
    best_val_score: float  # cfg.select_metric at best_epoch (val FG IoU in the reference recipe)
    history: list = field(default_factory=list)  # per-epoch dicts
    train_seconds: float = 0.0
    steps: list = field(default_factory=list)  # (metrics, step) to log afterwards (model.stacked); fit logs live
    # the best epoch's val (probs, labels): what `predict` gives with `model` (fit; None from model.stacked, whose
    # vmapped scores may differ from one model's in float order), so the post-hoc calibration need not score again
    val_scores: tuple | None = None


def fit(train: ClipSet, val: ClipSet, rest: np.ndarray, topo: ClipTopology, model_cfg: ModelConfig,
        cfg: TrainConfig, seed: int, log_metrics: Callable[[dict, int], None] | None = None,
        progress: bool = False) -> FitResult:
    """Train from scratch and return the model reloaded at its best validation FG IoU (top-1).

    `progress`: one tqdm bar over epochs x batches, the epoch's running mean loss in its postfix."""
    seed_everything(seed)
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    stats = norm_stats(train, rest, topo, cfg, rng)
    log.info("normalisation from %d %s clips, alpha %.4f", stats.n_clips, cfg.norm_stats, stats.alpha)
    model = STGNN(topo.clip_len, model_cfg).to(cfg.device)
    opt = torch.optim.Adam(param_groups(model, cfg.weight_decay), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.StepLR(opt, cfg.step_size, cfg.step_gamma) if cfg.schedule == "step" else None
    n_batches = -(-len(train) // cfg.batch_size)
    if cfg.train_batches:
        n_batches = min(n_batches, cfg.train_batches)
    best, best_state, best_epoch, history, step, best_scores = -1.0, None, -1, [], 0, None
    steps = bar(total=cfg.epochs * n_batches, desc="train", unit="batch", enabled=progress)
    for epoch in range(cfg.epochs):
        model.train()
        order = rng.permutation(len(train))  # without replacement within an epoch
        losses = []
        for b in range(n_batches):
            idx = order[b * cfg.batch_size:(b + 1) * cfg.batch_size]
            m, lab = training_batch(train, idx, cfg, rng)
            batch = make_batch(m, lab, rest, topo, stats, cfg.device)
            loss = train_step(model, opt, batch, stats.alpha, cfg.focal_gamma, pseudo_weight(cfg))
            losses.append(loss.item())
            step += 1
            if log_metrics:
                log_metrics({"train/loss": losses[-1]}, step)
            if progress:  # refresh=False: redraw only at update()'s mininterval (keeps logs small)
                steps.set_postfix_str(f"epoch {epoch + 1}/{cfg.epochs} loss {np.mean(losses):.5f}", refresh=False)
            steps.update()
        if sched:
            sched.step()
        probs, labels = predict(model, val, stats, rest, topo, cfg.batch_size, cfg.val_batches, cfg.device)
        row, score = epoch_row(epoch, losses, probs, labels, cfg)
        history.append(row)
        log.info("epoch %d: loss %.5f val %s %.4f", epoch, row["train/loss"], cfg.select_metric, score)
        if log_metrics:
            log_metrics({k: v for k, v in row.items() if k != "epoch"}, step)
        if score > best:  # strict, as Lightning's ModelCheckpoint in max mode
            best, best_epoch, best_scores = score, epoch, (probs, labels)
            best_state = copy.deepcopy(model.state_dict())
        elif cfg.patience and epoch - best_epoch >= cfg.patience:  # early stopping on the val split
            log.info("early stop after epoch %d: no better val %s for %d epochs", epoch, cfg.select_metric,
                     cfg.patience)
            break
    steps.close()
    model.load_state_dict(best_state)
    model.eval()
    return FitResult(model, stats, best_epoch, best, history, time.perf_counter() - start, val_scores=best_scores)
