"""Which process on this host owns something (an MLflow run, a temporary file), and is it still alive.

A hard-killed job (SIGKILL, a lost node) cannot clean up after itself; the next job checks the owner
recorded with the leftover and removes or closes it only when that process is gone.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path


def start_ticks(pid: int) -> str | None:
    """Start time of process `pid` in clock ticks (Linux /proc); None if there is no such live process
    (a zombie, dead but not yet reaped by its parent, counts as gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2:].split()  # proc(5): state is field 3, starttime field 22
    return None if fields[0] in ("Z", "X") else fields[19]


def pid_alive(pid: int) -> bool:
    """Whether process `pid` of this host exists (without /proc: any process by that number, even
    another user's)."""
    if Path("/proc/self/stat").exists():
        return start_ticks(pid) is not None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # e.g. another user's process
        return True
    return True


def process_id(pid: int | None = None) -> str:
    """host:pid:start-time; the start time tells a reused pid apart from the process that owned a thing."""
    pid = os.getpid() if pid is None else pid
    return f"{socket.gethostname()}:{pid}:{start_ticks(pid) or ''}"


def process_gone(ident: str) -> bool:
    """True only if the process `ident` ran on this host and no longer exists (other hosts: unknown)."""
    host, _, rest = ident.partition(":")
    pid, _, start = rest.partition(":")
    if host != socket.gethostname() or not pid.isdigit():
        return False
    if not pid_alive(int(pid)):
        return True
    now = start_ticks(int(pid))
    return bool(start) and now is not None and now != start
