"""Stress test of CPU twins stepping side by side in threads: `python -m palpation.twin.thread_stress --runs 300`.

One run is the body of tests/twin/test_resident.py::test_cpu_resident_twins_in_threads: a twin pressing into
the phantom alone (the reference bits), then `--twins` such twins spread over `--threads` threads, each built,
captured, stepped and read while the others do the same. A run fails when a thread raises, a twin's positions
differ from the reference by one bit, or a thread's Warp call falls inside another thread's capture
(CaptureWitness). Warp's CPU graph capture is process-wide (warp_runtime.CAPTURE_LOCK says why that matters), so
such a call either crashes or is recorded into the other twin's graph; this script makes such overlaps frequent. Too slow for CI (a run takes
1-3 s on two cores): tests/twin/test_thread_safety.py runs a short version.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext

import numpy as np
import warp as wp
from warp._src import context as warp_context

from palpation.twin.config import TwinConfig
from palpation.twin.mesh import cached_sensor_mesh
from palpation.twin.resident import CPU_TILES_LOCK
from palpation.twin.simulator import BatchedTwin


class CaptureWitness:
    """Counts the Warp calls (launch, copy, zero_, fill_) that one thread makes while another thread's graph
    capture is open: each is recorded into the other thread's graph (or crashes on the capture state it reads),
    whether or not the run's bits show it. Wraps Warp's functions for the duration of a `with` block."""

    WATCHED = [(wp, "launch"), (warp_context, "launch"), (wp, "copy"), (warp_context, "copy"),
               (wp.array, "zero_"), (wp.array, "fill_")]

    def __init__(self):
        self.foreign = 0  # Warp calls inside another thread's capture
        self._owner = None
        self._saved: list = []

    def __enter__(self) -> "CaptureWitness":
        def watch(fn):
            def watched(*args, **kwargs):
                if self._owner not in (None, threading.get_ident()):
                    self.foreign += 1  # a racy count is fine: any nonzero count is the defect
                return fn(*args, **kwargs)
            return watched

        begin, end = warp_context.capture_begin, warp_context.capture_end

        def capture_begin(*args, **kwargs):
            graph = begin(*args, **kwargs)
            self._owner = threading.get_ident()
            return graph

        def capture_end(*args, **kwargs):
            self._owner = None
            return end(*args, **kwargs)

        patches = [(owner, name, watch(getattr(owner, name))) for owner, name in self.WATCHED]
        patches += [(owner, name, fn) for owner in (wp, warp_context)
                    for name, fn in (("capture_begin", capture_begin), ("capture_end", capture_end))]
        self._saved = [(owner, name, getattr(owner, name)) for owner, name, _ in patches]
        for owner, name, fn in patches:
            setattr(owner, name, fn)
        return self

    def __exit__(self, *exc) -> None:
        for owner, name, fn in reversed(self._saved):
            setattr(owner, name, fn)


def press(mesh, kernel: str, frames: int = 4) -> np.ndarray:
    """Two envs pressing 0.5 mm a frame into the vessel (one without it): positions after each frame."""
    cfg = TwinConfig()
    cfg.integrator.kernel = kernel
    return press_frames(BatchedTwin(mesh, 2, cfg, {"vessel": np.array([1.0, 0.0])}, device="cpu"), frames)


def press_frames(sim: BatchedTwin, frames: int, held=()) -> np.ndarray:
    """A two-env twin from 0.5 mm above the phantom over the vessel, down 0.5 mm a frame: positions after each frame.
    `held`: frames stepped while this thread holds resident.CPU_TILES_LOCK (as another thread's twin would)."""
    scene = sim.cfg.scene
    T = np.tile(np.eye(4), (2, 1, 1))
    T[:, :3, :3] = np.diag([1.0, -1.0, -1.0])  # dome down
    T[:, :3, 3] = [scene.vessel_center_x, scene.vessel_center_y, scene.phantom_top_z + 0.0005]
    sim.reset(T)
    out = []
    for k in range(frames):
        T = T.copy()
        T[:, 2, 3] -= 0.0005
        with CPU_TILES_LOCK if k in held else nullcontext():
            sim.step_frame(T)
        out.append(sim.positions_world().copy())
    return np.array(out)


def one_run(mesh, kernel: str, reference: np.ndarray, twins: int, threads: int, frames: int) -> str | None:
    """None when every threaded twin gives the reference bits and no thread's Warp call fell inside another's
    capture, else what went wrong (one line)."""
    try:
        with CaptureWitness() as witness, ThreadPoolExecutor(threads) as pool:
            runs = list(pool.map(lambda _: press(mesh, kernel, frames), range(twins)))
    except Exception as exc:  # the race's crash: report it as a failed run, keep counting
        return f"{type(exc).__name__}: {exc} @ {traceback.extract_tb(exc.__traceback__)[-1].name}"
    bad = [i for i, got in enumerate(runs) if not np.array_equal(got, reference)]
    why = [f"twins {bad} differ from the reference"] if bad else []
    why += [f"{witness.foreign} Warp calls inside another thread's capture"] if witness.foreign else []
    return "; ".join(why) or None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=300, help="threaded runs (default 300)")
    parser.add_argument("--kernel", choices=["auto", "resident", "streamed"], default="auto",
                        help="twin.integrator.kernel (default auto: resident, streamed while another holds the tiles)")
    parser.add_argument("--twins", type=int, default=4, help="twins a run (default 4)")
    parser.add_argument("--threads", type=int, default=2, help="threads a run (default 2)")
    parser.add_argument("--frames", type=int, default=4, help="frames a twin (default 4)")
    parser.add_argument("--switch-interval", type=float, default=1e-5,
                        help="sys.setswitchinterval while the threads run (default 1e-5 s; Python's own is 5e-3): "
                             "threads take turns between any two bytecodes far more often, so overlaps are frequent")
    parser.add_argument("--out", help="write the counts as JSON here")
    args = parser.parse_args(argv)
    for name in ("runs", "twins", "threads", "frames"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be >= 1, got {getattr(args, name)}")
    mesh = cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))
    reference = press(mesh, args.kernel, args.frames)
    sys.setswitchinterval(args.switch_interval)
    failures: list[tuple[int, str]] = []
    start = time.perf_counter()
    for run in range(args.runs):
        why = one_run(mesh, args.kernel, reference, args.twins, args.threads, args.frames)
        if why:
            failures.append((run, why))
            print(f"run {run}: FAILED {why}", flush=True)
        if (run + 1) % 25 == 0:
            print(f"{run + 1}/{args.runs} runs, {len(failures)} failed, {time.perf_counter() - start:.0f} s", flush=True)
    wall = time.perf_counter() - start
    print(f"thread_stress kernel={args.kernel} twins={args.twins} threads={args.threads}: "
          f"{args.runs - len(failures)}/{args.runs} runs passed ({len(failures)} failed) in {wall:.0f} s")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"runs": args.runs, "failed": len(failures), "kernel": args.kernel, "twins": args.twins,
                       "threads": args.threads, "frames": args.frames, "switch_interval_s": args.switch_interval, "wall_s": round(wall, 1),
                       "failures": [{"run": r, "why": w} for r, w in failures]}, f, indent=1)
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
