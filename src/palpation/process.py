"""Which process on this host owns something (an MLflow run, a temporary file), and is it still alive.

A hard-killed job (SIGKILL, a lost node) cannot clean up after itself; the next job checks the owner
recorded with the leftover and removes or closes it only when that process is gone. psutil answers
portably; the process's creation time tells a reused pid apart from the owner.
"""

from __future__ import annotations

import os
import socket

import psutil


def start_time(pid: int) -> str | None:
    """Creation time of process `pid` (seconds, 2 decimals); None if there is no such live process
    (a zombie, dead but not yet reaped by its parent, counts as gone)."""
    try:
        proc = psutil.Process(pid)
        if proc.status() == psutil.STATUS_ZOMBIE:
            return None
        return f"{proc.create_time():.2f}"
    except (psutil.NoSuchProcess, psutil.ZombieProcess):
        return None
    except psutil.AccessDenied:  # another user's live process
        return ""


def pid_alive(pid: int) -> bool:
    """Whether process `pid` of this host exists and is not a zombie."""
    return start_time(pid) is not None


def process_id(pid: int | None = None) -> str:
    """host:pid:start-time; the start time tells a reused pid apart from the process that owned a thing."""
    pid = os.getpid() if pid is None else pid
    return f"{socket.gethostname()}:{pid}:{start_time(pid) or ''}"


def process_gone(ident: str) -> bool:
    """True only if the process `ident` ran on this host and no longer exists (other hosts: unknown)."""
    host, _, rest = ident.partition(":")
    pid, _, start = rest.partition(":")
    if host != socket.gethostname() or not pid.isdigit():
        return False
    now = start_time(int(pid))
    if now is None:
        return True
    return bool(start) and bool(now) and now != start
