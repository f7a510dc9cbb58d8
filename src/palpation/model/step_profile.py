"""Where one training step's time goes on this machine's CPU (issue 17: the quick profile's floor).

Times the step `train.fit` runs (`train.train_step`: forward, focal loss, backward, Adam) of one
configuration's model on real training batches, and lets torch's profiler split it by operator. Beside it, two
rates of the same machine and thread count: the matrix product of the model's widest layer (the edge encoders'
second Linear, one row per edge) in GFLOP/s, and the dropout mask of the largest dropout input (`bernoulli_`,
one double draw per element) against a uniform float draw of the same size. `--compile` also times the step
under torch.compile.

    python -m palpation.model.step_profile --configs A-to-A:large C-to-B:compact --override train.batch_size=4 \
        --compile --out docs/results/bench_train_step_cpu.json      # the quick profile's two kinds of training run
Inputs: the sets each experiment trains on (`--sim` for Sim; data.* overrides for the real sets). One record per
configuration, in a list.
"""

from __future__ import annotations

import argparse
import itertools
import logging
import platform
import statistics
import sys
import time

import numpy as np
import torch

from palpation.graph.batch import make_batch
from palpation.io import save_json
from palpation.model.benchmark import compose_job
from palpation.model.job import load_job_data
from palpation.model.stgnn import STGNN
from palpation.model.train import norm_stats, param_groups, seed_everything, train_step, training_batch
from palpation.tracking import git_commit

log = logging.getLogger(__name__)


def _ms(fn, repeats: int) -> float:
    """Median wall milliseconds of `fn()` over `repeats` calls, after one untimed call."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def training_batches(job, n: int) -> tuple[list, object]:
    """`n` training batches of random clips, augmented as `fit` augments them (seed 0), and the normalisation
    statistics `fit` would draw first."""
    d = load_job_data(job)
    seed_everything(0)
    rng = np.random.default_rng(0)
    stats = norm_stats(d.train, d.rest, d.topo, job.train, rng)
    batches = []
    for _ in range(n):
        idx = rng.choice(len(d.train), job.train.batch_size, replace=False)
        m, lab = training_batch(d.train, idx, job.train, rng)
        batches.append(make_batch(m, lab, d.rest, d.topo, stats, "cpu"))
    return batches, (d.topo, stats)


def step_timer(job, batches: list, topo, stats, compiled: bool = False):
    """A closure running one training step per call, cycling through `batches`; the model seeded as in `fit`."""
    seed_everything(0)
    model = STGNN(topo.clip_len, job.model).train()
    forward = torch.compile(model) if compiled else model
    opt = torch.optim.Adam(param_groups(model, job.train.weight_decay), lr=job.train.lr)
    turn = itertools.cycle(batches)

    def step():
        train_step(forward, opt, next(turn), stats.alpha, job.train.focal_gamma)
    return step, model


def by_operator(step, steps: int, top: int) -> list[dict]:
    """Self CPU milliseconds per step of the `top` costliest operators (torch.profiler), forward and backward."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(steps):
            step()
    rows = sorted(prof.key_averages(), key=lambda e: e.self_cpu_time_total, reverse=True)
    total = sum(e.self_cpu_time_total for e in rows)
    return [{"op": e.key, "self_ms_per_step": e.self_cpu_time_total / 1e3 / steps, "calls_per_step": e.count / steps,
             "share": e.self_cpu_time_total / total} for e in rows[:top]]


def machine_rates(job, batch, repeats: int) -> dict:
    """GEMM rate at the edge encoder's shape and the dropout mask's cost at the largest dropout input's."""
    rows, width = batch.edge_index.shape[1], job.model.encoder_width
    a, w = torch.randn(rows, width), torch.randn(width, width)
    gemm_ms = _ms(lambda: torch.nn.functional.linear(a, w), repeats)
    x = torch.randn(rows, job.model.latent_width)  # input_drop on the edges: one row per edge
    return {
        "gemm": {"shape": [rows, width, width], "ms": gemm_ms, "gflops": 2 * rows * width * width / gemm_ms / 1e6},
        "dropout": {"shape": list(x.shape), "p": job.model.input_dropout,
                    "dropout_ms": _ms(lambda: torch.nn.functional.dropout(x, job.model.input_dropout), repeats),
                    "rand_like_ms": _ms(lambda: torch.rand_like(x), repeats)},
    }


def profile_step(job, steps: int, top: int, compiled: bool) -> dict:
    batches, (topo, stats) = training_batches(job, 4)
    step, model = step_timer(job, batches, topo, stats)
    record = {"step_ms": _ms(step, steps)}
    with torch.inference_mode():
        record["eval_forward_ms"] = _ms(lambda: model.eval()(batches[0]), steps)
    model.train()
    record["by_operator"] = by_operator(step, steps, top)
    record["rates"] = machine_rates(job, batches[0], steps)
    b = batches[0]
    record["batch"] = {"clips": job.train.batch_size, "nodes": int(b.x.shape[0]), "edges": int(b.edge_index.shape[1])}
    if compiled:
        step, _ = step_timer(job, batches, topo, stats, compiled=True)
        t0 = time.perf_counter()
        step()
        # first_step_s includes the compilation (inductor's on-disk cache shortens a repeat)
        record["compiled"] = {"first_step_s": time.perf_counter() - t0, "step_ms": _ms(step, steps)}
    return record


def main(argv: list[str] | None = None) -> list[dict]:
    # argparse, as model.benchmark: a developer measurement outside the results DAG
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/results/bench_train_step_cpu.json")
    ap.add_argument("--configs", nargs="+", default=["A-to-A:large"], metavar="EXPERIMENT:MODEL",
                    help="conf/experiment/<EXPERIMENT>.yaml with conf/model/<MODEL>.yaml, one record each")
    ap.add_argument("--sim", default="results/sim/dataset/manifest.json", help="the Sim set's manifest")
    ap.add_argument("--override", nargs="*", default=[], help="more train-app overrides (key=value), every config")
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads (the quick profile: 1 a run)")
    ap.add_argument("--steps", type=int, default=12, help="timed calls per measurement")
    ap.add_argument("--top", type=int, default=12, help="operators listed")
    ap.add_argument("--compile", action="store_true", help="also time the step under torch.compile")
    args = ap.parse_args(argv)
    if any(c.count(":") != 1 for c in args.configs):
        raise SystemExit(f"step_profile: error: --configs {args.configs}: give EXPERIMENT:MODEL, e.g. A-to-A:large")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    torch.set_num_threads(args.threads)
    command = " ".join(["python -m palpation.model.step_profile", *(argv if argv is not None else sys.argv[1:])])
    records = []
    for config in args.configs:
        experiment, model = config.split(":")
        job = compose_job(experiment, "cpu", args.sim, [f"model={model}", "recipe=quick", *args.override])
        record = {"what": f"one training step of {job.config_name} ({job.model.name} model, batch "
                          f"{job.train.batch_size}) on the CPU, by operator, beside the machine's GEMM and "
                          "dropout-mask rates",
                  "cpu": platform.processor() or platform.machine(), "threads": torch.get_num_threads(),
                  "cpu_capability": torch.backends.cpu.get_cpu_capability(), "torch": torch.__version__,
                  "commit": git_commit(), **profile_step(job, args.steps, args.top, args.compile), "command": command}
        records.append(record)
        save_json(args.out, records)  # rewritten after each configuration
        rates = record["rates"]
        log.info("%s: step %.1f ms (eval forward %.1f ms); GEMM %.0f GFLOP/s; dropout %.1f ms vs rand_like %.1f ms%s",
                 config, record["step_ms"], record["eval_forward_ms"], rates["gemm"]["gflops"],
                 rates["dropout"]["dropout_ms"], rates["dropout"]["rand_like_ms"],
                 f"; compiled step {record['compiled']['step_ms']:.1f} ms" if args.compile else "")
    return records


if __name__ == "__main__":
    main()
