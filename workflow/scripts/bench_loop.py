"""Benchmark: the residual loop on the real flat-tip photos, timed end to end, written as JSON.

    python workflow/scripts/bench_loop.py --out docs/results/bench_loop_quick_cpu.json            # quick, CPU
    python workflow/scripts/bench_loop.py --profile paper --out OUT.json twin/mesh=reference twin.device=cuda

Runs `python -m palpation.apps.loop loop=PROFILE` (extra arguments are passed on as Hydra overrides) in a fresh
output folder, so no study is resumed, and records the command's wall time, the loop's own time and its time in the
twin (from the app's "done in" line), the machine's cores and the CPU affinity the run had. The aims it is read
against (docs/loop.md): the quick profile on two CPU cores no slower than 196.6 s, the paper profile <= 60 s on one
H100/H200. Nothing else is written to the record: one run, one timing.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DONE = re.compile(r"loop real done in (\d+) s \(.*?, ([\d.]+) s in the twin")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--profile", default="quick", choices=("quick", "paper", "tiny"))
    ap.add_argument("--out", type=Path, required=True, help="the JSON record")
    ap.add_argument("--keep", type=Path, help="a new folder the timed run's outputs are copied to (its report)")
    args, overrides = ap.parse_known_args()
    if args.keep is not None and args.keep.exists():
        raise SystemExit(f"bench_loop: --keep {args.keep} exists; name a new folder")
    with tempfile.TemporaryDirectory(prefix="bench_loop_") as tmp:
        cmd = [sys.executable, "-m", "palpation.apps.loop", f"loop={args.profile}", f"out.dir={tmp}/out",
               f"hydra.run.dir={tmp}/hydra", "track=false", "progress=false", *overrides]
        start = time.perf_counter()
        run = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - start
        log = run.stdout + run.stderr
        if run.returncode != 0:
            tail = log.strip().splitlines()[-1] if log.strip() else "no output"
            raise SystemExit(f"bench_loop: the loop failed (exit {run.returncode}): {tail}")
        table = (Path(tmp) / "out" / "loop_real.csv").read_text()
        if args.keep is not None:
            shutil.copytree(Path(tmp) / "out", args.keep)
            (args.keep / "loop.log").write_text(log)
    found = DONE.search(log)
    if not found:
        raise SystemExit("bench_loop: no 'loop real done in' line in the app's log; the app's log format changed")
    record = {"what": f"python -m palpation.apps.loop loop={args.profile} on the flat-tip photos, from a fresh output "
                      "folder, timed end to end", "command": " ".join(["python", *cmd[1:4], *cmd[6:]]),
              "wall_s": round(wall, 1), "loop_s": int(found.group(1)), "twin_s": float(found.group(2)),
              "cpu_count": os.cpu_count(), "cpu_affinity": len(os.sched_getaffinity(0)),
              "machine": platform.machine(), "python": platform.python_version(), "loop_real_csv": table}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=1) + "\n")
    print(f"loop={args.profile}: {record['wall_s']} s wall, {record['loop_s']} s in the loop, "
          f"{record['twin_s']:.0f} s in the twin ({record['cpu_affinity']} of {record['cpu_count']} cores) -> {args.out}")


if __name__ == "__main__":
    main()
