"""run_parts: parts side by side in threads, results in the parts' order; usable_cores: the threads a process may use."""

import threading

import pytest

from palpation.twin.warp_runtime import run_parts, usable_cores


def test_parts_run_side_by_side():
    barrier = threading.Barrier(2, timeout=10)

    def fn(x):
        barrier.wait()  # both parts at once, else BrokenBarrierError
        return 2 * x

    results, ran_on = run_parts(fn, [1, 2], workers=2)
    assert results == [2, 4] and ran_on == [0, 1]


@pytest.mark.parametrize("workers, parts", [(1, [1, 2, 3]), (4, [5])])
def test_one_worker_or_one_part_runs_here(workers, parts):
    here = threading.get_ident()
    results, ran_on = run_parts(lambda x: (x, threading.get_ident()), parts, workers)
    assert results == [(x, here) for x in parts] and ran_on == [0] * len(parts)


def test_usable_cores_follow_the_jobs_threads(monkeypatch):
    """Snakemake sets OMP_NUM_THREADS to a job's threads: the CPU twin's worker threads stay within them."""
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    cores = usable_cores()
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert usable_cores() == 1
    monkeypatch.setenv("OMP_NUM_THREADS", str(cores + 8))
    assert usable_cores() == cores
    for junk in ("", "0", "two"):
        monkeypatch.setenv("OMP_NUM_THREADS", junk)
        assert usable_cores() == cores
