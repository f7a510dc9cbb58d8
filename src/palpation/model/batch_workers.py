"""Each seed's training batches built in a process of its own (issue 17).

On a GPU a stacked step (`model.stacked`) waits for its seeds' batches longer than for the card: one
batch (gather, augmentation, features, normalisation) is tens of milliseconds of numpy, and threads
cannot build the seeds' batches side by side under the GIL. A `SeedFeed` forks one worker per seed.
The worker takes the seed's fresh numpy stream and draws exactly what `fit_seeds` would, in the same
order: the normalisation clips (so the seeds' statistics are computed side by side), then each epoch's
permutation and each batch's augmentation. It writes the batch's `STEP_FIELDS` into a ring of shared-memory slots;
the training process copies a slot into pinned memory and hands the slot back.

The worker may run ahead across an epoch's end: a seed's draws do not depend on its training, and the
batches of a seed that stopped early are never read. The worker only runs numpy (never CUDA), so it
is safe to fork from a process that holds a CUDA context.
"""

from __future__ import annotations

import mmap
import multiprocessing as mp
import os
import queue
import traceback
import warnings

import numpy as np
import torch

from palpation.graph.batch import STEP_FIELDS, step_arrays
from palpation.graph.clips import ClipSet
from palpation.graph.edges import ClipTopology
from palpation.graph.features import clip_features
from palpation.graph.normalise import NormStats
from palpation.model.config import TrainConfig
from palpation.model.train import norm_stats, training_batch

SLOTS = 3  # batches a worker may have ready: enough to hide a slow one, little shared memory (3 x ~8 MB)
POLL_S = 5.0  # how often a waiting process checks that the other one is still alive


def _slot_views(buffer: mmap.mmap, shapes: dict) -> dict[str, np.ndarray]:
    """float32 views of one slot's fields (full-batch shapes) laid end to end in `buffer`."""
    views, offset = {}, 0
    for name in STEP_FIELDS:
        n = int(np.prod(shapes[name]))
        views[name] = np.frombuffer(buffer, np.float32, n, offset).reshape(shapes[name])
        offset += 4 * n
    return views


def _free_slot(empty, parent: int) -> int | None:
    """The next slot to fill; None when told to stop or when the training process is gone (killed outright, it
    could not say so, and a worker blocked for ever would outlive it)."""
    while True:
        try:
            return empty.get(timeout=POLL_S)
        except queue.Empty:
            if os.getppid() != parent:
                return None


def _build(train: ClipSet, rest: np.ndarray, topo: ClipTopology, cfg: TrainConfig, rng: np.random.Generator,
           n_batches: int, slots: list, empty, full, parent: int) -> None:
    """The worker: its seed's statistics, then epoch after epoch its batches, in `fit_seeds`' draw order, until
    told to stop."""
    try:
        stats = norm_stats(train, rest, topo, cfg, rng)
        full.put(("stats", stats))
        while True:
            order = rng.permutation(len(train))
            for b in range(n_batches):
                slot = _free_slot(empty, parent)
                if slot is None:
                    return
                m, lab = training_batch(train, order[b * cfg.batch_size:(b + 1) * cfg.batch_size], cfg, rng)
                for name, a in step_arrays(m, lab, rest, topo, stats).items():
                    slots[slot][name][:len(a)] = a
                full.put((slot, len(m)))
    except BaseException:  # the training process raises it, with the worker's traceback
        full.put(("error", traceback.format_exc()))


class SeedFeed:
    """One seed's batch worker and its ring of shared-memory slots; `next()` gives the seed's next batch."""

    def __init__(self, seed: int, train: ClipSet, rest: np.ndarray, topo: ClipTopology, cfg: TrainConfig,
                 rng: np.random.Generator, n_batches: int, shapes: dict, pin: bool):
        self.seed, self.pin = seed, pin
        self.per_clip = {name: shape[0] // cfg.batch_size for name, shape in shapes.items()}
        size = 4 * sum(int(np.prod(s)) for s in shapes.values())
        self.buffers = [mmap.mmap(-1, size) for _ in range(SLOTS)]  # anonymous and shared: the fork sees them
        self.slots = [_slot_views(buf, shapes) for buf in self.buffers]
        ctx = mp.get_context("fork")  # the worker inherits the clips (copy-on-write), nothing is pickled
        self.empty, self.full = ctx.Queue(), ctx.Queue()
        for k in range(SLOTS):
            self.empty.put(k)
        self.proc = ctx.Process(target=_build, name=f"batches-seed{seed}", daemon=True,
                                args=(train, rest, topo, cfg, rng, n_batches, self.slots, self.empty, self.full,
                                      os.getpid()))
        with warnings.catch_warnings():  # Python warns on any fork of a threaded process; the child runs numpy only
            warnings.simplefilter("ignore", DeprecationWarning)
            self.proc.start()

    def _get(self) -> tuple:
        """The worker's next message; its error (or silent death) raised here."""
        while True:
            try:
                got = self.full.get(timeout=POLL_S)
                break
            except queue.Empty:
                if not self.proc.is_alive():
                    raise RuntimeError(f"the batch worker of seed {self.seed} died (exit code "
                                       f"{self.proc.exitcode}) without a word") from None
        if got[0] == "error":
            raise RuntimeError(f"the batch worker of seed {self.seed} failed:\n{got[1]}")
        return got

    def stats(self) -> NormStats:
        """The seed's normalisation statistics (the worker's first message; call once, before `next`)."""
        kind, stats = self._get()
        if kind != "stats":
            raise RuntimeError(f"the batch worker of seed {self.seed} sent a batch before its statistics")
        return stats

    def next(self) -> dict[str, torch.Tensor]:
        """The seed's next batch: its STEP_FIELDS as CPU tensors (pinned when `pin`), the slot handed back."""
        slot, n_clips = self._get()
        out = {}
        for name, view in self.slots[slot].items():
            part = torch.from_numpy(view[:n_clips * self.per_clip[name]])
            out[name] = part.pin_memory() if self.pin else part.clone()  # a copy: the slot is reused at once
        self.empty.put(slot)
        return out

    def close(self) -> None:
        self.empty.put(None)
        self.proc.join(timeout=2.0)
        if self.proc.is_alive():  # blocked on a full ring: nothing of it is wanted any more
            self.proc.terminate()
            self.proc.join()
        for q in (self.empty, self.full):
            q.close()
            q.join_thread()
        self.slots, self.buffers, self.proc = [], [], None  # the maps go with their last view


def step_shapes(train: ClipSet, rest: np.ndarray, topo: ClipTopology, batch_size: int,
                remove_common_motion: bool) -> dict[str, tuple]:
    """Full-batch shape of every STEP_FIELD, from one unaugmented batch (no draw from any seed's stream)."""
    idx = np.arange(min(batch_size, len(train)))
    m, lab = train.gather(idx)
    feats = clip_features(m, rest, topo, remove_common_motion)
    stats = NormStats.from_chunks([(feats, lab)], "full", remove_common_motion)  # any statistics: same shapes
    arrays = step_arrays(m, lab, rest, topo, stats, feats)
    return {name: (a.shape[0] // len(idx) * batch_size, *a.shape[1:]) for name, a in arrays.items()}
