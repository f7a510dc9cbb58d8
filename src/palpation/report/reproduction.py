"""Wall time of a workflow run, per rule, from Snakemake's own job metadata.

Snakemake records start and end times of every job in `.snakemake/metadata/`; the Snakefile's
`onstart` stamps the run's start and `onsuccess` calls `record_run`, which sums job durations per rule
for jobs of this run and writes `results/bench/reproduction.json` (one record per profile and device).
"""

from __future__ import annotations

import json
import time
from collections import Counter
from pathlib import Path

from palpation.io import save_json, save_text
from palpation.tracking import git_commit

STAMP = "results/bench/.run_start"


def stamp_start(workdir: str | Path = ".") -> None:
    save_text(Path(workdir) / STAMP, f"{time.time()}\n")


def jobs_since(metadata_dir: Path, since: float) -> dict[int, dict]:
    """One entry per job (outputs of a job share its hash) started at or after `since`."""
    jobs: dict[int, dict] = {}
    for path in metadata_dir.glob("*"):
        try:
            meta = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        start, end = meta.get("starttime"), meta.get("endtime")
        if start is None or end is None or start < since or meta.get("incomplete"):
            continue
        jobs[meta.get("job_hash", hash(path.name))] = {"rule": meta["rule"], "s": end - start}
    return jobs


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
    workdir = Path(workdir)
    stamp = workdir / STAMP
    since = float(stamp.read_text()) if stamp.exists() else 0.0
    per_rule: dict[str, float] = {}
    for job in jobs_since(workdir / ".snakemake" / "metadata", since).values():
        per_rule[job["rule"]] = per_rule.get(job["rule"], 0.0) + job["s"]
    record = {"profile": profile, "device": device, "wall_s": round(time.time() - since, 1),
              "per_rule": {k: round(v, 1) for k, v in sorted(per_rule.items())}, "commit": git_commit()}
    out = workdir / "results" / "bench" / "reproduction.json"
    records = json.loads(out.read_text()) if out.exists() else []
    records = [r for r in records if (r["profile"], r["device"]) != (profile, device)] + [record]
    save_json(out, records)
    return record
