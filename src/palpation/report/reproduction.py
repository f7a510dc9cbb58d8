"""Wall time of a workflow run, per rule, from Snakemake's `benchmark:` files.

Every rule names `benchmark: results/benchmarks/<rule>.tsv` (or `<rule>/<wildcards>.tsv` for a rule with
wildcards); Snakemake writes the job's wall seconds (`s`), peak memory (`max_rss`, MB) and CPU time there
when the job succeeds. The results page reads these files (so a page built inside a run already has the
run's jobs); the Snakefile's `onstart` stamps the run's start and `onsuccess` calls `record_run`, which sums
this run's jobs per rule into `results/bench/reproduction.json` (one record per profile and device; the
committed docs/results/bench_reproduction.json is such a file).
"""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path

import pandas as pd

from palpation.io import save_json, save_text
from palpation.readers import read_csv, read_json, read_text
from palpation.tracking import git_commit

STAMP = "bench/.run_start"  # under the results root
BENCHMARKS = "benchmarks"  # under the results root
JOB_COLUMNS = ["rule", "job", "s", "max_rss", "cpu_time", "end"]
STAMP_FIX = "delete it; the next `snakemake` run writes it again (onstart)"


def stamp_start(workdir: str | Path = ".") -> None:
    save_text(Path(workdir) / "results" / STAMP, f"{time.time()}\n")


def run_start(results: str | Path) -> float | None:
    """The start of the latest run (`onstart`'s stamp) under a results root, or None."""
    stamp = Path(results) / STAMP
    if not stamp.exists():
        return None
    text = read_text(stamp, STAMP_FIX, "run-start stamp").strip()
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"run-start stamp {stamp} holds {text[:40]!r}, not a time in seconds; {STAMP_FIX}") from None


def benchmark_jobs(results: str | Path) -> pd.DataFrame:
    """One row per job whose benchmark file is on disk (the job that made the outputs there): rule, job
    (its wildcards, '' for a rule without), s (wall seconds), max_rss (MB), cpu_time (s) and end (the file's
    mtime, s since the epoch: Snakemake writes it when the job ends)."""
    root = Path(results) / BENCHMARKS
    rows = []
    for path in sorted(root.rglob("*.tsv")):
        rel = path.relative_to(root)
        table = read_csv(path, fix="delete it and rerun its rule", what="Snakemake benchmark file", rows=False,
                         sep="\t", na_values=["-"])
        if "s" not in table.columns or table.empty:
            raise ValueError(f"{path}: no `s` column or no row; Snakemake's benchmark files have both; "
                             "delete it and rerun its rule")
        last = table.iloc[-1]  # `benchmark: repeat(...)` writes one row per repeat; the last is this run's job
        rows.append({"rule": rel.parts[0].removesuffix(".tsv"), "job": "/".join(rel.with_suffix("").parts[1:]),
                     "s": float(last["s"]), "max_rss": float(last.get("max_rss", float("nan"))),
                     "cpu_time": float(last.get("cpu_time", float("nan"))), "end": path.stat().st_mtime})
    return pd.DataFrame(rows, columns=JOB_COLUMNS)


def per_rule(jobs: pd.DataFrame) -> pd.DataFrame:
    """Jobs, summed wall seconds and the largest peak memory per rule, the slowest rule first."""
    out = jobs.groupby("rule").agg(jobs=("s", "size"), s=("s", "sum"), max_rss=("max_rss", "max"))
    return out.sort_values("s", ascending=False)


def span_s(jobs: pd.DataFrame) -> float:
    """Seconds from the first job's start (its end minus its wall time) to the last job's end."""
    return float(jobs["end"].max() - (jobs["end"] - jobs["s"]).min()) if len(jobs) else 0.0


def job_stats(log: str) -> Counter:
    """Jobs per rule from the first "Job stats" table of a Snakemake log (a dry run's or a run's);
    empty when Snakemake had nothing to do."""
    lines = log.splitlines()
    try:
        start = lines.index("Job stats:") + 3  # header and rule lines follow
    except ValueError:
        return Counter()
    counts: Counter = Counter()
    for line in lines[start:]:
        name, _, count = line.rpartition(" ")
        if name.strip() == "total":
            if int(count) != sum(counts.values()):
                raise ValueError(f"job stats: total {count} is not the sum of {dict(counts)}")
            return counts
        counts[name.strip()] += int(count)
    raise ValueError("job stats: no total line")


def record_run(profile: str, device: str, workdir: str | Path = ".") -> dict:
    """Append this run's record (jobs whose benchmark file was written since `onstart`) to
    results/bench/reproduction.json, replacing the profile's and device's previous one."""
    results = Path(workdir) / "results"
    since = run_start(results) or 0.0
    jobs = benchmark_jobs(results)
    times = per_rule(jobs[jobs["end"] >= since])["s"]
    record = {"profile": profile, "device": device, "wall_s": round(time.time() - since, 1),
              "per_rule": {k: round(float(v), 1) for k, v in sorted(times.items())}, "commit": git_commit()}
    out = results / "bench" / "reproduction.json"
    records = read_json(out, "delete it (the next run writes a new one)", kind=list, optional=True) or []
    if any(not isinstance(r, dict) or not {"profile", "device"} <= r.keys() for r in records):
        raise ValueError(f"{out}: every record needs `profile` and `device`; delete it (the next run writes a new one)")
    records = [r for r in records if (r["profile"], r["device"]) != (profile, device)] + [record]
    save_json(out, records)
    return record
