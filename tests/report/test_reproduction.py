"""Rule timings from Snakemake's benchmark files: the results page's Timing section and record_run."""

import json
import os
from pathlib import Path

import pytest

from palpation.paths import REPO_ROOT
from palpation.report import reproduction
from palpation.report.results_page import build_page

PAGE_CONF = REPO_ROOT / "conf" / "results_page"


def timing(root: Path, rec: dict | None, built_commit: str) -> str:
    """The rendered page's Timing section, with `rec` as the run's only reproduction record."""
    if rec is not None:
        (root / "bench").mkdir(parents=True, exist_ok=True)
        (root / "bench" / "reproduction.json").write_text(json.dumps([rec]))
    text, _ = build_page(root, PAGE_CONF / "explanations.yaml", PAGE_CONF / "folders.yaml", built_commit=built_commit)
    return text.split("## Timing")[1].split("\n## ")[0]

HEADER = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"


def bench(results: Path, rel: str, s: float, end: float, rss: str = "512.5") -> None:
    """A benchmark file as Snakemake 9 writes it, ending at `end` (its mtime)."""
    path = results / "benchmarks" / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(HEADER + f"{s}\t0:00:01\t{rss}\t900\t400\t410\t1.0\t2.0\t80.0\t{s * 0.9}\n")
    os.utime(path, (end, end))


def tree(results: Path) -> Path:
    bench(results, "calibrate.tsv", 100.0, end=1_000.0)
    bench(results, "train/A-to-B_L5_seed0.tsv", 40.0, end=1_050.0)
    bench(results, "train/A-to-B_L5_seed1.tsv", 30.0, end=1_060.0, rss="NA")  # Snakemake's NA: nothing sampled
    bench(results, "mesh/mesh_coarse.tsv", 5.0, end=800.0)  # made before the run's start below
    (results / "bench").mkdir(parents=True)
    (results / "bench" / ".run_start").write_text("850.0\n")
    return results


def test_jobs_and_rules_from_the_benchmark_files(tmp_path):
    jobs = reproduction.benchmark_jobs(tree(tmp_path / "results"))
    assert sorted(jobs["rule"]) == ["calibrate", "mesh", "train", "train"]
    assert set(jobs[jobs.rule == "train"]["job"]) == {"A-to-B_L5_seed0", "A-to-B_L5_seed1"}
    rules = reproduction.per_rule(jobs)
    assert list(rules.index) == ["calibrate", "train", "mesh"]  # slowest first
    assert rules.loc["train", "jobs"] == 2 and rules.loc["train", "s"] == 70.0
    assert rules.loc["train", "max_rss"] == 512.5  # the NA job does not hide the other's peak
    assert reproduction.span_s(jobs) == 1_060.0 - 795.0  # mesh started at 800 - 5


def test_page_times_a_fresh_run_from_its_benchmark_files(tmp_path):
    text = timing(tree(tmp_path / "results"), None, "abc")
    assert "No timing record" not in text
    assert "| calibrate | 1 | 100.0 | 512 |" in text and "| train | 2 | 70.0 | 512 |" in text
    assert "4 jobs" in text and "1 of them made by an earlier invocation" in text and "265.0 s" in text


def test_page_without_benchmarks_uses_the_record_or_says_none(tmp_path):
    rec = {"profile": "quick", "device": "cpu", "wall_s": 700.0, "per_rule": {"train": 300.0}, "commit": "aaa"}
    assert "wall time 700.0 s" in timing(tmp_path, rec, "bbb") and "| train | 300.0 |" in timing(tmp_path, rec, "b")
    assert "exceed the wall time); here the record's commit differs" in timing(tmp_path, rec, "bbb")
    assert "exceed the wall time).\n\n| rule | s |" in timing(tmp_path, rec, "aaa")
    (tmp_path / "empty").mkdir()
    assert "No timing record for this profile" in timing(tmp_path / "empty", None, "bbb")


def test_record_run_sums_only_this_runs_jobs(tmp_path, monkeypatch):
    tree(tmp_path / "results")
    monkeypatch.setenv("PALPATION_GIT_COMMIT", "c0ffee")
    record = reproduction.record_run("tiny", "cpu", tmp_path)
    assert record["per_rule"] == {"calibrate": 100.0, "train": 70.0} and record["commit"] == "c0ffee"
    saved = json.loads((tmp_path / "results/bench/reproduction.json").read_text())
    assert saved == [record]


def test_a_broken_benchmark_file_names_itself(tmp_path):
    path = tmp_path / "benchmarks" / "loop.tsv"
    path.parent.mkdir(parents=True)
    path.write_text("wall\n3\n")
    with pytest.raises(ValueError, match=r"loop\.tsv: no `s` column.*rerun its rule"):
        reproduction.benchmark_jobs(tmp_path)
