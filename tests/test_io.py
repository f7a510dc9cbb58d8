"""Atomic writes: nothing half-written is left, and a killed writer's temporary goes at the next write."""

import subprocess
import sys

import pytest

from palpation import io


def test_failed_write_leaves_nothing(tmp_path):
    target = tmp_path / "table.csv"
    with pytest.raises(RuntimeError):
        with io.atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []


def test_next_write_removes_temps_of_dead_writers_only(tmp_path):
    target = tmp_path / "scores.npz"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)
    stale = tmp_path / (io._temp_prefix(target, int(dead.stdout)) + "abc.npz")
    live = tmp_path / (io._temp_prefix(target) + "def.npz")  # this process: a writer still at work
    other = tmp_path / ".scores.npz.notes"  # not one of ours
    for f in (stale, live, other):
        f.write_text("partial")
    io.save_text(target, "done\n")
    assert target.read_text() == "done\n"
    assert not stale.exists() and live.exists() and other.exists()
