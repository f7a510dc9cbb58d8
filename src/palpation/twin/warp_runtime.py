"""Warp's runtime, started once; on a machine without a CUDA driver its native warning is dropped.

Warp's library prints "Could not find or load the NVIDIA CUDA driver" from C to stderr on every CPU
start, so every CPU log would open with a warning about hardware the run never asked for. The runtime
is started here with stderr captured at the file-descriptor level; every other line is passed on.
"""

from __future__ import annotations

import functools
import logging
import os
import sys
import tempfile
import threading

import warp as wp

log = logging.getLogger(__name__)
# Warp's CPU graph capture is process-wide state: threads that each run a twin (loop.simulate, apps.simulate)
# build, capture and read their twins under this lock and replay their graphs outside it (Warp replays a CPU
# graph natively, without Python's lock, one core per thread)
CAPTURE_LOCK = threading.Lock()


def usable_cores() -> int:
    """Cores this process may run on (its affinity where the OS has one): the CPU twin's threads."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)

CPU_ONLY_WARNING = b"Could not find or load the NVIDIA CUDA driver"


@functools.cache
def init_warp() -> None:
    """`wp.init()` once, minus the CPU-only driver warning (Warp's banner and any other message stay)."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        for line in captured.read().splitlines(keepends=True):
            if CPU_ONLY_WARNING not in line:
                os.write(2, line)


def resolve_device(name: str):
    """`cuda` when present, else the CPU (the configs say cuda for the paper profile)."""
    init_warp()
    if str(name).startswith("cuda") and not wp.is_cuda_available():
        log.warning("device %r requested but CUDA is not available: running on the CPU", name)
        name = "cpu"
    return wp.get_device(name)
