"""Twins in threads never make a Warp call inside another thread's graph capture (warp_runtime.CAPTURE_LOCK).

Warp's capture state is one process-wide global: a launch, copy or zero_ of one thread during another thread's
capture is recorded into that graph, or crashes when the capture ends between its check and its use. That crash
was rare (once in three runs of the twin tests), the recording silent; CaptureWitness counts every such call,
and with threads switching every 10 us the code before the fix made 45-158 of them in every threaded twin run here
(the Sim-set writer's and the loop's paths, through LockedBatch, made none then either: kept as regression tests).
`python -m palpation.twin.thread_stress --runs 300` is the long version.
"""

import os
import sys

import numpy as np
import pytest

from palpation.loop.simulate import LoopSimulator, State, loop_twin_config
from palpation.markers.template import rest_template
from palpation.twin import thread_stress
from palpation.twin.config import TwinConfig
from palpation.twin.runner import EnvRequest, run_batches
from palpation.twin.thread_stress import CaptureWitness


@pytest.fixture
def fast_switching():
    """Threads take turns every 10 us instead of 5 ms: overlaps of their Warp calls become frequent."""
    saved = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)
    yield
    sys.setswitchinterval(saved)


def test_witness_sees_a_call_inside_another_threads_capture(mesh):
    """The witness itself: a copy made by a second thread while this one captures is counted."""
    import threading

    import warp as wp

    a = wp.zeros(3, dtype=float, device="cpu")
    b = wp.zeros(3, dtype=float, device="cpu")
    with CaptureWitness() as witness:
        with wp.ScopedCapture(device="cpu"):
            wp.copy(a, b)  # this thread's own call: not foreign
            other = threading.Thread(target=lambda: wp.copy(b, a))
            other.start()
            other.join()
    assert witness.foreign >= 1


@pytest.mark.parametrize("kernel", ["auto", "resident", "streamed"])
def test_twins_in_threads_stay_out_of_each_others_captures(mesh, kernel, fast_switching):
    reference = thread_stress.press(mesh, kernel)
    for _ in range(3):
        assert thread_stress.one_run(mesh, kernel, reference, twins=4, threads=2, frames=4) is None


def test_sim_set_batches_in_threads_stay_out_of_each_others_captures(mesh, fast_switching):
    """The Sim-set writer's path (run_batches cut in worker threads, marker extraction captured per frame)."""
    slides = [EnvRequest("slide", heading_offset_deg=h, name=f"s{i}") for i, h in enumerate([5.0, -3.0, 0.0, 8.0])]
    with CaptureWitness() as witness:
        many = run_batches(mesh, TwinConfig(), slides, 4, device="cpu", progress=False, max_frames=6, workers=2)
    assert witness.foreign == 0 and sum(len(r.records) for r in many) == 4


def test_loop_simulator_in_threads_stays_out_of_each_others_captures(fast_switching):
    """The residual loop's path (LoopSimulator: pooled twins, LockedBatch, two worker threads)."""
    from palpation.twin.mesh import cached_sensor_mesh

    mesh = cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))
    press = State("press_d4", "press", 4.0)
    jobs = [(press, {"E": e}) for e in (1.0e6, 1.2e6, 1.5e6, 2.0e6)]
    sim = LoopSimulator(mesh, loop_twin_config(TwinConfig(), 1.5e-3), rest_template(), device="cpu", max_frames=4,
                        workers=2, cache_bytes=0)
    with CaptureWitness() as witness:
        first, _ = sim.simulate(jobs)
        again, _ = sim.simulate(jobs)  # on the pooled twins
    assert witness.foreign == 0
    np.testing.assert_array_equal(first, again)
