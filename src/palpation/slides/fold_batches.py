"""The slide loop's folds sharing their twin calls (conf/slide_loop.yaml `batch_folds`): each fold runs in a thread,
and a call waits until every fold still running has one; the last to arrive runs them all as one twin batch.

Why: a call holds 50-60 envs (6 effects x 2 asks x 5 trials). On CUDA the streamed kernels cost about linearly in
the envs from there, and two fold processes only take turns on the card (one H100: a 50-env call 8.5-9.1 s alone,
a 60-env call 19-20 s beside the other fold's). The frame-resident kernel runs any batch up to one wave (264
reference envs on an H100) in about one env's time, so one call of both folds' 100-120 envs costs about what one
fold's did (docs/twin.md).
The folds share nothing else; an env's result does not depend on its batch (slides.replay.replay_many), so on the CPU
the loop gives the same bits as one fold after the other.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

EvaluateMany = Callable[[list[tuple]], list[tuple]]  # [(sequence set, candidates)] -> [(markers, failed)]


class FoldBatches:
    """`evaluate(part, candidates)` for each fold thread; `many` runs the gathered calls as one."""

    def __init__(self, many: EvaluateMany, n_folds: int):
        self._many, self._running, self._waiting = many, n_folds, []
        self._cv = threading.Condition()

    def __call__(self, part, candidates):
        slot = {"job": (part, candidates)}
        with self._cv:
            self._waiting.append(slot)
            self._run_if_all_wait()
            self._cv.wait_for(lambda: "out" in slot or "error" in slot)
        if "error" in slot:
            raise RuntimeError("a shared twin call of the slide loop's folds failed") from slot["error"]
        return slot["out"]

    def fold_done(self) -> None:
        with self._cv:
            self._running -= 1
            self._run_if_all_wait()

    def _run_if_all_wait(self) -> None:  # under the lock: every other running fold is blocked in its call
        if not self._waiting or len(self._waiting) < self._running:
            return
        slots, self._waiting = self._waiting, []
        try:
            for slot, out in zip(slots, self._many([s["job"] for s in slots])):
                slot["out"] = out
        except Exception as exc:  # every waiting fold fails with it, none waits forever
            for slot in slots:
                slot["error"] = exc
        self._cv.notify_all()


def run_folds_together(run_fold: Callable, jobs: list[tuple], many: EvaluateMany) -> list:
    """`run_fold(evaluate, *rest)` for each job (evaluate first), the folds in threads sharing their twin calls."""
    batches = FoldBatches(many, len(jobs))

    def one(job):
        try:
            return run_fold(batches, *job[1:])
        finally:
            batches.fold_done()

    with ThreadPoolExecutor(len(jobs)) as pool:
        return list(pool.map(one, jobs))
