"""Warp's runtime, started once; on a machine without a CUDA driver its native warning is dropped.

Warp's library prints "Could not find or load the NVIDIA CUDA driver" from C to stderr on every CPU
start, so every CPU log would open with a warning about hardware the run never asked for. The runtime
is started here with stderr captured at the file-descriptor level; every other line is passed on.
"""

from __future__ import annotations

import functools
import os
import sys
import tempfile

import warp as wp

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
