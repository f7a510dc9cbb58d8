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
from concurrent.futures import ThreadPoolExecutor

import warp as wp

log = logging.getLogger(__name__)
# Warp's graph capture is process-wide state: one global (runtime._apic_capture in Warp 1.19) that every launch,
# copy, zero_ and allocation consults. A Warp call of one thread while another thread captures is recorded into
# that thread's graph (and replayed with it), or dies when the capture ends between the call's check and its use
# (wp.copy: 'NoneType' has no attribute 'track_array'). So every Warp call of a twin holds this lock: BatchedTwin
# takes it in each of its methods (warp_exclusive), and only the replay of a captured graph runs outside it (Warp
# replays a CPU graph natively, without Python's lock, one core per thread). Reentrant: LockedBatch holds it
# around a twin's whole setup and reads. thread_stress.CaptureWitness counts calls that break the rule.
CAPTURE_LOCK = threading.RLock()


def warp_exclusive(method):
    """`method` run under CAPTURE_LOCK: for every method that makes Warp calls other than replaying a graph."""

    @functools.wraps(method)
    def locked(*args, **kwargs):
        with CAPTURE_LOCK:
            return method(*args, **kwargs)

    return locked


def usable_cores() -> int:
    """Cores this process may run on (its affinity where the OS has one): the CPU twin's threads. At most
    OMP_NUM_THREADS where set: Snakemake sets it to a job's `threads:`, so the jobs running side by side do not
    oversubscribe the cores (a second twin thread in a one-thread job only ran frames the other core's job
    needed, on the slower streamed kernels: resident.frame_kernel)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    omp = os.environ.get("OMP_NUM_THREADS", "")
    return min(cores, int(omp)) if omp.isdigit() and int(omp) > 0 else cores


def run_parts(fn, parts: list, workers: int) -> tuple[list, list[int]]:
    """`fn(part)` for each part, in order: side by side in `workers` threads when there are several workers and
    parts (a thread takes the next part as it frees, so give the longest first), else one by one here.

    Returns the results and, per part, the worker that ran it (numbered by first use; all 0 one by one)."""
    if workers <= 1 or len(parts) <= 1:
        return [fn(p) for p in parts], [0] * len(parts)
    ran_on = [0] * len(parts)

    def one(i):
        ran_on[i] = threading.get_ident()
        return fn(parts[i])

    with ThreadPoolExecutor(workers) as pool:
        results = list(pool.map(one, range(len(parts))))
    number: dict[int, int] = {}
    return results, [number.setdefault(t, len(number)) for t in ran_on]


CPU_ONLY_WARNING = b"Could not find or load the NVIDIA CUDA driver"


@functools.cache
def init_warp() -> None:
    """`wp.init()` once, minus the CPU-only driver warning (Warp's banner and any other message stay).

    PALPATION_WARP_CPU_FLAGS, where set, replaces Warp's CPU compiler flags (default "-march=native ..."): ""
    compiles the CPU kernels for a generic x86-64, as another host's CPU would round (the reproducibility
    contract's cross-host check, docs/DEVELOPING.md)."""
    if "PALPATION_WARP_CPU_FLAGS" in os.environ:
        wp.config.cpu_compiler_flags = os.environ["PALPATION_WARP_CPU_FLAGS"]
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
