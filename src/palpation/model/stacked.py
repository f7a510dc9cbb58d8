"""Several seeds of one configuration trained together in one process (issue 17).

The seeds' models are stacked (`torch.func.stack_module_state`) and every training step is one
vmapped `functional_call` over the stack, so a GPU runs S small models as one set of kernels instead
of S processes taking turns. Everything that makes a seed a seed stays its own, drawn exactly as
`train.fit` draws it: normalisation clips, epoch orders and augmentation (its numpy stream), the
initial weights (torch seeded with the seed), the dropout masks (its own RNG state, in the forward's
order), the Adam moments (elementwise, so one Adam over stacked tensors is S Adams), early stopping
and the best-validation checkpoint. Validation and test scoring run the stack too (`score_stack`).

The host stays a step ahead of the card: the seeds' next batches are built (and pinned) on threads while
the current step runs, and the losses are read back once an epoch instead of once a step (a read-back
waits for the card). The draws are unchanged: each seed's batches are still built in order from its
own stream, never across an epoch's end.

How close to separate runs: every draw is the same. Dropout masks are drawn by `F.dropout` itself
(on ones, so the CPU's `bernoulli_` or CUDA's fused kernel, with the same shapes in the same order)
from the seed's own copy of the default generator's state, which is where `fit`'s dropouts draw from.
Only the batched matrix products round differently (~1e-7 relative per forward on the CPU), which
training can amplify (tests/model/test_stacked.py: weights within ~2e-6, val scores within 1e-7 after
three Adam steps, the same checkpoint epochs and val counts); on CUDA, scatter atomics add their usual
run-to-run noise.
"""

from __future__ import annotations

import copy
import logging
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from types import SimpleNamespace

import numpy as np
import torch
from torch import nn
from torch.func import functional_call, stack_module_state, vmap

from palpation.graph.batch import STEP_FIELDS, global_counts, make_batch, step_arrays
from palpation.graph.clips import ClipSet
from palpation.graph.edges import ClipTopology
from palpation.graph.features import clip_features
from palpation.model.batch_workers import SeedFeed, step_shapes
from palpation.model.config import ModelConfig, TrainConfig
from palpation.model.evaluate import aligned_features, central_slice
from palpation.model.stgnn import STGNN
from palpation.model.train import (FitResult, epoch_row, focal_loss, grouped_parameters, norm_stats,
                                   pseudo_focal_loss, pseudo_weight, seed_everything, training_batch)
from palpation.progress import bar

log = logging.getLogger(__name__)
# validation batches kept between epochs, per job (the paper profile's robust Sim job: 43 batches x 5 seeds, ~1.9 GB)
VAL_CACHE_BYTES = 2 * 1024 ** 3


class GivenNoise(nn.Module):
    """Dropout whose scaled keep-masks are handed in (one per call, in call order) instead of drawn."""

    def __init__(self, p: float, feed: dict):
        super().__init__()
        self.p, self.feed = p, feed

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.feed.get("record") is not None:  # shape probe: list the masks a forward needs
            if self.p > 0:
                self.feed["record"].append((tuple(x.shape), self.p))
            return x
        if not self.training or self.p == 0:  # F.dropout draws nothing here either
            return x
        return x * self.feed["masks"].pop(0)


def noisy_copy(model: STGNN, feed: dict) -> STGNN:
    """A weightless copy of `model` (for functional_call) whose dropouts take masks from `feed`."""
    base = copy.deepcopy(model).to("meta")
    for name, module in list(base.named_modules()):
        if isinstance(module, nn.Dropout):
            parent, _, child = name.rpartition(".")
            setattr(base.get_submodule(parent) if parent else base, child, GivenNoise(module.p, feed))
    return base


@dataclass
class SeedState:
    """What one seed owns during joint training."""

    seed: int
    rng: np.random.Generator
    stats: object
    rng_state: torch.Tensor  # its dropout stream: the default generator's state in its own fit
    best: float = -1.0
    best_state: dict | None = None
    best_epoch: int = -1
    history: list = field(default_factory=list)
    steps: list = field(default_factory=list)  # (metrics, step) to replay into its MLflow run
    stopped: bool = False
    batch: object = None  # its latest batch


class Stack:
    """The seeds' models stacked: one vmapped forward runs them all, each on its own batch."""

    def __init__(self, models: list[STGNN]):
        self.params, self.buffers = stack_module_state(models)
        self.feed: dict = {"record": None, "masks": []}
        self.base = noisy_copy(models[0], self.feed)
        self.shapes: dict = {}  # dropout masks one forward takes, per batch size

    def _one(self, p, b, x, ea_s, ea_t, ea_g, masks, like):
        self.feed["masks"] = list(masks)
        graph = SimpleNamespace(x=x, edge_attr_spatial=ea_s, edge_attr_temporal=ea_t, edge_attr_global_temporal=ea_g,
                                edge_index=like.edge_index, num_global=like.num_global,
                                num_global_spatial=like.num_global_spatial)  # the structure all seeds share
        return functional_call(self.base, (p, b), (graph,))

    def mask_shapes(self, like) -> list:
        """(shape, p) of every dropout call of one forward on batches like `like`, in call order."""
        key = (like.x.shape[0], like.edge_index.shape[1])
        if key not in self.shapes:
            self.feed["record"], training = [], self.base.training
            self.base.eval()  # the probe must not update running statistics
            with torch.no_grad():
                self._one({k: v[0] for k, v in self.params.items()}, {k: v[0] for k, v in self.buffers.items()},
                          *(getattr(like, f) for f in STEP_FIELDS[:-1]), [], like)
            self.shapes[key], self.feed["record"] = self.feed["record"], None
            self.base.train(training)
        return self.shapes[key]

    def __call__(self, batches: list, masks: list | None = None) -> torch.Tensor:
        """Logits (S, n_marker_nodes) of seed i's model on batches[i]; `masks` per dropout call (S, ...)."""
        like = batches[0]
        if any(b.x.shape != like.x.shape for b in batches):
            raise ValueError("seeds run together need batches of one size (same split and batch_size)")
        fields = [torch.stack([getattr(b, f) for b in batches]) for f in STEP_FIELDS[:-1]]
        return vmap(partial(self._one, like=like), randomness="error")(self.params, self.buffers, *fields,
                                                                      masks or [])


def _rng_state(device: str) -> torch.Tensor:
    d = torch.device(device)
    return torch.get_rng_state() if d.type == "cpu" else torch.cuda.get_rng_state(d)


def _set_rng_state(state: torch.Tensor, device: str) -> None:
    d = torch.device(device)
    torch.set_rng_state(state) if d.type == "cpu" else torch.cuda.set_rng_state(state, d)


def _draw_masks(s: SeedState, shapes: list, device: str) -> list[torch.Tensor]:
    """The scaled keep-masks seed `s`'s own forward would draw: F.dropout on ones from its RNG state."""
    _set_rng_state(s.rng_state, device)
    masks = [torch.nn.functional.dropout(torch.ones(shape, device=device), p, training=True)
             for shape, p in shapes]
    s.rng_state = _rng_state(device)
    return masks


def _start_seeds(train: ClipSet, rest: np.ndarray, topo: ClipTopology, model_cfg: ModelConfig, cfg: TrainConfig,
                 seeds: list[int], n_batches: int, workers: bool) -> tuple[list, list, list]:
    """Every seed's state and initial model, with its batch worker if `workers`, in `fit`'s draw order: seeding,
    normalisation clips, initial weights. A worker takes the seed's stream over from the start: it draws the
    normalisation clips itself (the seeds' statistics in parallel) and then the batches."""
    shapes = step_shapes(train, rest, topo, cfg.batch_size, cfg.remove_common_motion) if workers else None
    states, models, feeds = [], [], []
    try:
        for seed in seeds:
            seed_everything(seed)
            rng = np.random.default_rng(seed)
            if workers:
                pin = torch.device(cfg.device).type == "cuda"  # pinned copies: the step need not wait for them
                feeds.append(SeedFeed(seed, train, rest, topo, cfg, rng, n_batches, shapes, pin))
                rng, stats = None, None  # the stream is the worker's now; its statistics come below
            else:
                stats = norm_stats(train, rest, topo, cfg, rng)
            models.append(STGNN(topo.clip_len, model_cfg).to(cfg.device))  # torch's stream: numpy drew nothing here
            # where fit's dropouts start drawing: the CPU generator after the init, the seeded CUDA one
            states.append(SeedState(seed, rng, stats, _rng_state(cfg.device)))
        for s, feed in zip(states, feeds):
            s.stats = feed.stats()
    except BaseException:
        for feed in feeds:
            feed.close()
        raise
    return states, models, feeds


def fit_seeds(train: ClipSet, val: ClipSet, rest: np.ndarray, topo: ClipTopology, model_cfg: ModelConfig,
              cfg: TrainConfig, seeds: list[int], progress: bool = False,
              batch_workers: bool | None = None) -> list[FitResult]:
    """`train.fit` for every seed in `seeds`, trained together; one FitResult per seed, in order.

    Each result's `steps` lists the (metrics, step) that `fit` would have logged while training.
    batch_workers: build each seed's batches in a process of its own (model.batch_workers; the same draws);
    None: on a GPU only (on a 2-core CPU the workers would take the cores the training needs)."""
    if len(set(seeds)) != len(seeds) or not seeds:
        raise ValueError(f"seeds must be distinct and at least one, got {seeds}")
    start = time.perf_counter()
    on_gpu = torch.device(cfg.device).type == "cuda"
    n_batches = -(-len(train) // cfg.batch_size)
    if cfg.train_batches:
        n_batches = min(n_batches, cfg.train_batches)
    states, models, feeds = _start_seeds(train, rest, topo, model_cfg, cfg, seeds, n_batches,
                                         on_gpu if batch_workers is None else batch_workers)
    stack = Stack(models)

    weight = pseudo_weight(cfg)

    def seed_loss(logits, y, alpha):
        if weight is not None:  # label codes with pseudo-labels (recipe.pseudo)
            return pseudo_focal_loss(logits, y, alpha, cfg.focal_gamma, weight)
        return focal_loss(logits, y, alpha, cfg.focal_gamma)

    def prepare(i: int, order: np.ndarray, b: int):  # only seed i's own stream: threads are safe
        s = states[i]
        if s.stopped:
            return None
        if feeds:
            return feeds[i].next()
        m, lab = training_batch(train, order[b * cfg.batch_size:(b + 1) * cfg.batch_size], cfg, s.rng)
        host = {k: torch.from_numpy(v) for k, v in step_arrays(m, lab, rest, topo, s.stats).items()}
        return {k: v.pin_memory() for k, v in host.items()} if on_gpu else host  # pinned: the copy need not wait

    def prepare_all(orders: list, b: int) -> list:
        return list(pool.map(prepare, range(len(states)), orders, [b] * len(states)))

    edge_index = {}  # clips in a batch -> the batch's edges on the device (the same for every seed and step)
    val_batches = {}  # the seeds' val batches: the same every epoch (score_stack's cache)

    def on_device(host: dict) -> SimpleNamespace:
        b = len(host["y"]) // topo.n_markers  # marker nodes per clip
        if b not in edge_index:
            edge_index[b] = torch.as_tensor(topo.batched_edge_index(b), dtype=torch.long, device=cfg.device)
        return SimpleNamespace(**{k: v.to(cfg.device, non_blocking=True) for k, v in host.items()},
                               edge_index=edge_index[b], **global_counts(topo, b))

    opt = torch.optim.Adam(grouped_parameters(stack.params.items(), cfg.weight_decay), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.StepLR(opt, cfg.step_size, cfg.step_gamma) if cfg.schedule == "step" else None
    alphas = torch.tensor([s.stats.alpha for s in states], dtype=torch.float32, device=cfg.device)
    steps = bar(total=cfg.epochs * n_batches, desc=f"train {len(seeds)} seeds", unit="batch", enabled=progress)
    step, pool = 0, ThreadPoolExecutor(len(states))  # the seeds' batches are built side by side
    ahead = ThreadPoolExecutor(1)  # ... one step ahead of the card: batch b + 1 is built while step b runs
    try:
        for epoch in range(cfg.epochs):
            stack.base.train()
            orders = [None if s.stopped or feeds else s.rng.permutation(len(train)) for s in states]
            # a stopped seed's loss weighs 0, fixed within an epoch
            active = torch.tensor([0.0 if s.stopped else 1.0 for s in states], device=cfg.device)
            step_losses = []  # (step, the seeds' losses on the device): read back once an epoch, not once a step
            coming = ahead.submit(prepare_all, orders, 0)
            for b in range(n_batches):
                host = coming.result()
                if b + 1 < n_batches:  # not across epochs: the next epoch's order is drawn after this one's batches
                    coming = ahead.submit(prepare_all, orders, b + 1)
                for s, h in zip(states, host):
                    if h is not None:
                        s.batch = on_device(h)
                idle = next(s.batch for s in states if not s.stopped)
                batches = [idle if s.stopped else s.batch for s in states]  # a stopped seed idles, weight 0
                shapes = stack.mask_shapes(batches[0])
                drawn = [_draw_masks(s, shapes, cfg.device) for s in states]
                logits = stack(batches, [torch.stack(per_call) for per_call in zip(*drawn)])
                loss = vmap(seed_loss)(logits, torch.stack([x.y for x in batches]), alphas)
                opt.zero_grad()
                (loss * active).sum().backward()  # seeds share no weights: each gets its own gradient
                opt.step()
                step += 1
                step_losses.append((step, loss.detach()))
                steps.update()
            losses = [[] for _ in states]
            values = torch.stack([v for _, v in step_losses]).tolist() if step_losses else []
            for (at, _), per_seed in zip(step_losses, values):
                for s, lst, value in zip(states, losses, per_seed):
                    if not s.stopped:
                        lst.append(value)
                        s.steps.append(({"train/loss": value}, at))
            if progress:
                live = [np.mean(lst) for s, lst in zip(states, losses) if not s.stopped]
                steps.set_postfix_str(f"epoch {epoch + 1}/{cfg.epochs} loss {np.mean(live):.5f}")
            if sched:
                sched.step()
            scored = score_stack(stack, [s.stats for s in states], val, rest, topo, cfg.batch_size, cfg.val_batches,
                                 cfg.device, cache=val_batches)
            stack.base.train()
            for i, (s, lst) in enumerate(zip(states, losses)):
                if not s.stopped:
                    _validate(s, i, epoch, lst, step, stack, *scored[i], cfg)
            if all(s.stopped for s in states):
                break
    finally:  # a failed step (or worker) leaves no worker process behind
        for feed in feeds:
            feed.close()
        steps.close()
        pool.shutdown()
        ahead.shutdown()
    seconds = time.perf_counter() - start
    results = []
    for s in states:
        model = STGNN(topo.clip_len, model_cfg).to(cfg.device)
        model.load_state_dict(s.best_state)
        model.eval()
        results.append(FitResult(model, s.stats, s.best_epoch, s.best, s.history, seconds, s.steps))
    return results


def _validate(s: SeedState, i: int, epoch: int, losses: list, step: int, stack: Stack, probs: np.ndarray,
              labels: np.ndarray, cfg: TrainConfig) -> None:
    """`fit`'s end of epoch for seed i from its val scores: keep the best weights, maybe stop early."""
    row, score = epoch_row(epoch, losses, probs, labels, cfg)
    s.history.append(row)
    s.steps.append(({k: v for k, v in row.items() if k != "epoch"}, step))
    log.info("seed %d epoch %d: loss %.5f val %s %.4f", s.seed, epoch, row["train/loss"], cfg.select_metric, score)
    if score > s.best:  # strict, as fit
        s.best, s.best_epoch = score, epoch
        s.best_state = {k: v[i].detach().clone() for k, v in {**stack.params, **stack.buffers}.items()}
    elif cfg.patience and epoch - s.best_epoch >= cfg.patience:
        log.info("seed %d: early stop after epoch %d", s.seed, epoch)
        s.stopped = True


def predict_seeds(models: list[STGNN], stats: list, clips: ClipSet, rest: np.ndarray, topo: ClipTopology,
                  batch_size: int, device: str = "cpu", progress: bool = False,
                  align=None) -> list[tuple[np.ndarray, np.ndarray]]:
    """`evaluate.predict` of every seed's model on the same clips, all seeds in one vmapped forward per
    batch; per seed (probs, labels). `align`: as `evaluate.predict`'s."""
    return score_stack(Stack(models), stats, clips, rest, topo, batch_size, None, device, progress, align=align)


@torch.no_grad()
def score_stack(stack: Stack, stats: list, clips: ClipSet, rest: np.ndarray, topo: ClipTopology, batch_size: int,
                max_batches: int | None = None, device: str = "cpu", progress: bool = False,
                cache: dict | None = None, align=None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Central-frame scores of the stacked models (eval mode) as `predict` gives them one model at a time;
    the clip features are computed once, each seed normalises them with its own statistics.

    cache: scoring the same clips with the same statistics again (validation, every epoch) reuses the seeds'
    batches kept here from the last call, up to VAL_CACHE_BYTES on `device`; the rest are built again."""
    if len({st.remove_common_motion for st in stats}) > 1:  # one set of features serves every seed
        raise ValueError("score_stack: the stacked seeds' statistics disagree on remove_common_motion; "
                         "stack only runs of one recipe")
    stack.base.eval()
    centre = central_slice(topo.clip_len)
    n = len(clips) if max_batches is None else min(len(clips), max_batches * batch_size)
    probs, labels = [], []
    for start in bar(range(0, n, batch_size), desc=f"score {len(stats)} seeds", unit="batch", enabled=progress):
        idx = np.arange(start, min(start + batch_size, n))
        if cache is not None and start in cache:
            batches, lab, _ = cache[start]
        else:
            markers, lab = clips.gather(idx)
            feats = clip_features(markers, rest, topo, stats[0].remove_common_motion) if align is None \
                else aligned_features(align, clips, idx, markers, rest, topo, stats[0].remove_common_motion)
            batches = [make_batch(markers, lab, rest, topo, st, device, features=feats) for st in stats]
            if cache is not None:  # each entry keeps its size: the total is a sum of ints, not of tensors
                size = _bytes(batches)
                if sum(kept[2] for kept in cache.values()) + size <= VAL_CACHE_BYTES:
                    cache[start] = batches, lab, size
        p = torch.sigmoid(stack(batches)).view(len(stats), len(idx), topo.n_markers)[:, :, centre]
        probs.append(p.cpu().numpy().reshape(len(stats), -1))
        labels.append(lab.reshape(len(idx), -1)[:, centre].ravel())
    labels = np.concatenate(labels).astype(np.int8)
    return [(p, labels) for p in np.concatenate(probs, axis=1).astype(np.float32)]


def _bytes(batches: list) -> int:
    return sum(v.numel() * v.element_size() for b in batches for v in b.to_dict().values() if torch.is_tensor(v))

