"""Training jobs spread over a host's GPUs: `device=cuda` takes the least busy card, not always card 0.

Snakemake runs several GPU jobs side by side (the profile's `gpu` resource) but assigns no card, so on a
host with several GPUs every job would land on cuda:0. A job whose device is plain `cuda` claims a slot
instead: an exclusive `flock` on <lock dir>/cuda<i>.slot<k>, tried slot by slot (k), card by card (i), so
the first jobs take slot 0 of every card and the next ones the card with the fewest jobs. The lock is held
by an open file until the process exits, so a killed job frees its slot; nothing is ever cleaned up by hand.
An explicit card (`cuda:1`), the CPU and a one-GPU host are left as they are.
"""

from __future__ import annotations

import fcntl
import logging
import os
import tempfile
from pathlib import Path

log = logging.getLogger(__name__)
MAX_SLOTS = 64  # jobs per card before a job stops looking and shares slot 0 of card 0
_HELD: list = []  # the open lock files: closing one (process exit) frees its slot


def lock_dir() -> Path:
    """Where the slot locks live: PALPATION_GPU_LOCKS, else <tmp>/palpation-gpu-slots (one per host)."""
    return Path(os.environ.get("PALPATION_GPU_LOCKS") or Path(tempfile.gettempdir()) / "palpation-gpu-slots")


def claim_slot(n_devices: int, where: Path) -> int:
    """Index of the card whose lowest free slot is lowest (ties: lowest index); the slot stays held."""
    where.mkdir(parents=True, exist_ok=True)
    for slot in range(MAX_SLOTS):
        for card in range(n_devices):
            f = open(where / f"cuda{card}.slot{slot}", "w")
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                f.close()
                continue
            _HELD.append(f)
            return card
    log.warning("all %d slots of %d GPUs in %s are held: using cuda:0", MAX_SLOTS, n_devices, where)
    return 0


def shared_cuda(device: str) -> str:
    """`cuda:<i>` for the card this job claims when `device` is plain `cuda` on a host with several
    visible GPUs; `device` unchanged otherwise."""
    if device != "cuda":
        return device
    import torch

    n = torch.cuda.device_count()
    if n < 2:
        return device
    where = lock_dir()
    card = claim_slot(n, where)
    torch.cuda.set_device(card)  # where code that says plain `cuda` allocates
    log.info("device cuda -> cuda:%d (%d GPUs visible; slot locks in %s)", card, n, where)
    return f"cuda:{card}"
