"""The whole workflow, for real, with the tiny profile: a hard kill and resume, bit-identical reruns,
exact reruns after a config edit, and the report (issue 8, "Reliability").

One module-scoped fixture makes two runs of `rule all` in temporary copies of the checkout: run 1 is
killed with SIGKILL of Snakemake's whole process group in the middle of the residual loop's search (its
MLflow run open, an Optuna batch running, earlier jobs finished), then resumed (the profile sets
rerun-incomplete); run 2 is a clean run. About 5 min on 2 CPU cores.
Deselect with: python -m pytest -m "not workflow".
"""

import csv
import io
import json
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from collections import Counter
from contextlib import closing
from pathlib import Path
from types import SimpleNamespace

import optuna
import pytest
import yaml

from palpation.paths import REPO_ROOT
from palpation.report import reproduction
from palpation.report.reproduction import job_stats

pytestmark = pytest.mark.workflow

SNAKEMAKE = [sys.executable, "-m", "snakemake", "--workflow-profile", "workflow/profiles/tiny"]
TIMING_COLUMN = re.compile(r"wall_s")  # measured wall times (trials.csv): the only field that may differ
JOB = re.compile(r"^(?:local)?rule (\w+):\n(.*?)\n    jobid: (\d+)$", re.M | re.S)


def checkout(dest: Path) -> Path:
    dest.mkdir()
    for name in ("Snakefile", "workflow", "data"):
        os.symlink(REPO_ROOT / name, dest / name)
    shutil.copytree(REPO_ROOT / "conf", dest / "conf")  # the rerun test edits configs
    return dest


def environ(work: Path) -> dict:
    return {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}",
            "PALPATION_RESULTS": str(work / "results"), "PYTHONUNBUFFERED": "1",
            "MLFLOW_TRACKING_URI": f"sqlite:///{work / 'results' / 'mlflow.db'}"}


def snakemake(work: Path, *args: str) -> str:
    out = subprocess.run(SNAKEMAKE + list(args), cwd=work, env=environ(work), stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-4000:]
    return out.stdout


def jobs(log: str) -> dict[int, tuple[str, list[str]]]:
    """jobid -> (rule, output paths) of every job a Snakemake log started."""
    out = {}
    for rule, body, jobid in JOB.findall(log):
        outputs = re.search(r"^    output: (.*)$", body, re.M)
        out[int(jobid)] = (rule, outputs.group(1).split(", ") if outputs else [])
    return out


def finished(log: str) -> set[int]:
    return {int(j) for j in re.findall(r"^Finished jobid: (\d+) ", log, re.M)}


def db_query(db: Path, sql: str) -> list[tuple]:
    if not db.exists():
        return []
    try:
        with closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=5)) as con:
            return con.execute(sql).fetchall()
    except sqlite3.Error:  # being created or written
        return []


def study_states(path: Path) -> Counter:
    """Trials per state (COMPLETE, RUNNING, ...) over every study of an Optuna journal file."""
    if not path.exists():
        return Counter()
    storage = optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(str(path)))
    return Counter(t.state.name for name in optuna.get_all_study_names(storage)
                   for t in optuna.load_study(study_name=name, storage=storage).get_trials(deepcopy=False))


RUNS_SQL = ("SELECT r.run_uuid, e.name, r.status FROM runs r JOIN experiments e"
            " ON r.experiment_id = e.experiment_id")


def loop_mid_search(work: Path) -> bool:
    """The loop's MLflow run is open and its Optuna study holds completed and running trials."""
    runs = db_query(work / "results" / "mlflow.db", RUNS_SQL)
    if not any(e == "loop" and s == "RUNNING" for _, e, s in runs):
        return False
    states = study_states(work / "results" / "loop" / "study.journal")
    return states.get("COMPLETE", 0) > 0 and states.get("RUNNING", 0) > 0


def mtimes(results: Path) -> dict[str, int]:
    return {str(p.relative_to(results.parent)): p.stat().st_mtime_ns for p in results.rglob("*")}


def kill_and_resume(work: Path) -> SimpleNamespace:
    log_path = work / "killed.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen(SNAKEMAKE, cwd=work, env=environ(work), stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)  # its own process group, jobs included
    deadline = time.monotonic() + 600
    while not loop_mid_search(work):
        assert proc.poll() is None, "the workflow ended before the loop's search ran: nothing to kill"
        assert time.monotonic() < deadline, "the loop's search did not start within 10 min"
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    for _ in range(100):  # the jobs die with their group; wait until the kernel has removed them
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    killed = SimpleNamespace(log=log_path.read_text(), mtimes=mtimes(work / "results"),
                             incomplete=list((work / ".snakemake" / "incomplete").glob("*")),
                             orphans={r for r, _, s in db_query(work / "results" / "mlflow.db", RUNS_SQL)
                                      if s == "RUNNING"})
    # Snakemake's lock outlives a SIGKILL: the documented recovery is --unlock, then the rerun
    snakemake(work, "--unlock")
    killed.resume_log = snakemake(work)
    return killed


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("workflow")
    killed = checkout(root / "killed")
    first = kill_and_resume(killed)
    clean = checkout(root / "clean")
    clean_log = snakemake(clean)
    return SimpleNamespace(killed=killed, first=first, clean=clean, clean_log=clean_log)


def test_resume_redoes_only_what_the_kill_left_unfinished(runs):
    first = runs.first
    assert first.incomplete, "the kill should have left jobs marked incomplete"
    started, done = jobs(first.log), finished(first.log)
    assert done and set(started) - done, "the kill should fall after some jobs finished, while others ran"
    # the resume's jobs are the whole DAG's minus those that finished before the kill
    expected = job_stats(first.log) - Counter(started[j][0] for j in done)
    assert job_stats(first.resume_log) == expected
    resumed = jobs(first.resume_log)
    for rule, outputs in (started[j] for j in set(started) - done):  # running at the kill: redone
        assert any(r == rule and o == outputs for r, o in resumed.values()), f"{rule} {outputs} not redone"
        for path in outputs:
            assert (runs.killed / path).stat().st_mtime_ns != first.mtimes.get(path), f"{path} kept"
    for rule, outputs in (started[j] for j in done):  # finished before the kill: untouched
        for path in outputs:
            assert (runs.killed / path).stat().st_mtime_ns == first.mtimes[path], f"{rule}: {path} rewritten"


def test_resumed_run_is_complete_and_clean(runs):
    work = runs.killed
    for rule, outputs in jobs(runs.clean_log).values():  # every output of the DAG, as a clean run lists it
        for path in outputs:
            assert (work / path).exists(), f"{rule}: {path} missing after the resume"
    assert not list((work / ".snakemake" / "incomplete").glob("*")), "incomplete markers left"
    # palpation.io writes through hidden temporaries; a killed writer's is removed by the rerun's write
    hidden = [p for p in (work / "results").rglob(".*")
              if p.is_file() and p.name not in (".snakemake_timestamp", ".run_start")]
    assert not hidden, f"temporary files left behind: {hidden}"
    assert "Nothing to be done" in snakemake(work, "-n")
    # the loop's batch cut by the kill was simulated again with its recorded proposals, not failed
    states = study_states(work / "results" / "loop" / "study.journal")
    assert states.get("COMPLETE") and not states.get("FAIL") and not states.get("RUNNING"), states


def current_runs(work: Path) -> list:
    import mlflow

    client = mlflow.MlflowClient(tracking_uri=f"sqlite:///{work / 'results' / 'mlflow.db'}")
    exps = [e.experiment_id for e in client.search_experiments()]
    return client.search_runs(exps, max_results=10_000)


def test_mlflow_no_run_lost_or_duplicated(runs):
    killed = current_runs(runs.killed)
    status = {r.info.run_id: r.info.status for r in killed}
    assert runs.first.orphans, "the kill should have left at least the loop's run RUNNING"
    assert {status[r] for r in runs.first.orphans} == {"KILLED"}, "orphaned runs must be marked KILLED"
    assert "RUNNING" not in status.values()
    assert all(s in ("FINISHED", "KILLED") for s in status.values())

    def finished_by_job(runs_):
        current = [r for r in runs_ if r.info.status == "FINISHED" and "superseded_by" not in r.data.tags]
        return (Counter(r.data.tags["job_key"] for r in current),
                Counter(r.data.tags["snakemake_rule"] for r in current))

    keys, per_rule = finished_by_job(killed)
    assert max(keys.values()) == 1, "a job has two current FINISHED runs"
    clean_keys, clean_per_rule = finished_by_job(current_runs(runs.clean))
    assert per_rule == clean_per_rule, "the resumed store must hold the clean run's runs, one per job"
    assert set(keys) == set(clean_keys)
    assert "none" not in per_rule, "every workflow run is tagged with its Snakemake rule"


def tables(work: Path) -> dict[str, str]:
    """Every CSV/Markdown table the DAG wrote under results/ (not MLflow's artefact copies)."""
    out = {}
    for path in sorted((work / "results").rglob("*")):
        rel = path.relative_to(work)
        if path.suffix not in (".csv", ".md") or rel.parts[1] == "mlartifacts":
            continue
        text = path.read_text()
        if rel == Path("results/README.md"):  # the page's timing section is measured, the rest must match
            head, _, rest = text.partition("\n## Timing\n")
            text = head + rest[rest.find("\n## "):]
        if path.suffix == ".csv":
            rows = list(csv.reader(io.StringIO(text)))
            keep = [i for i, name in enumerate(rows[0]) if not TIMING_COLUMN.search(name)] if rows else []
            text = "\n".join(",".join(row[i] for i in keep) for row in rows)
        out[str(rel)] = text
    return out


def test_same_profile_twice_gives_identical_tables(runs):
    first, second = tables(runs.killed), tables(runs.clean)
    assert len(first) >= 10 and "results/calibration/calibration.csv" in first
    assert sorted(first) == sorted(second)
    differ = [name for name in first if first[name] != second[name]]
    assert not differ, f"tables differ between a killed+resumed and a clean run: {differ}"


def test_every_job_timed_by_its_benchmark_file(runs):
    """Snakemake's benchmark files time a fresh run: the page built inside it has the timing (no "No timing
    record"), and onsuccess's record sums every rule of the run."""
    ran = Counter(rule for rule, _ in jobs(runs.clean_log).values() if rule != "all")
    timed = reproduction.benchmark_jobs(runs.clean / "results")
    assert Counter(timed["rule"]) == ran and (timed["s"] > 0).all()
    page = (runs.clean / "results" / "README.md").read_text()
    section = page.split("\n## Timing\n")[1].split("\n## ")[0]
    assert "No timing record" not in section
    for rule in set(ran) - {"results_page"}:  # the page's own job ends after the page
        assert f"| {rule} | {ran[rule]} | " in section, f"{rule} missing from the page's timing"
    record = json.loads((runs.clean / "results" / "bench" / "reproduction.json").read_text())[-1]
    assert set(record["per_rule"]) == set(ran) and record["profile"] == "tiny"


def edit_reruns(work: Path, path: str, change) -> Counter:
    """Dry-run job counts after `change(text) -> text` of conf file `path`; the file is then restored."""
    target = work / path
    before, stat = target.read_text(), target.stat()
    after = change(before)
    assert after != before, f"the edit of {path} changed nothing"
    target.write_text(after)
    try:
        return job_stats(snakemake(work, "-n"))
    finally:
        target.write_text(before)
        os.utime(target, ns=(stat.st_atime_ns, stat.st_mtime_ns))


def test_changed_config_reruns_exactly_the_affected_rules(runs):
    work = runs.clean
    assert job_stats(snakemake(work, "-n")) == Counter(), "a finished run has nothing left to do"
    assert edit_reruns(work, "conf/vessel_maps.yaml",
                       lambda t: t.replace("min_pixels: 20", "min_pixels: 21")) == Counter(vessel_maps=1, results_page=1, all=1)
    assert edit_reruns(work, "conf/calibration/tiny.yaml",
                       lambda t: t.replace("n_trials: 3", "n_trials: 4")) == Counter(calibrate=1, results_page=1, all=1)

    def bigger_large_model(text):
        cfg = yaml.safe_load(text)
        cfg["train"]["sizes"]["large"]["train_batches"] += 1
        return yaml.safe_dump(cfg)

    tiny = yaml.safe_load((work / "conf/workflow/tiny.yaml").read_text())
    profile = tiny["train"]

    def is_large(e):
        return "override /model: large" in (work / f"conf/experiment/{e}.yaml").read_text()

    large = [e for e in profile["experiments"] if is_large(e)]
    assert 0 < len(large) < len(profile["experiments"])  # the edit must leave a train job alone
    expected = Counter(train_report=1, vessel_maps=1, results_page=1, all=1)
    main = {(e, s) for e in large for s in profile["seeds"]}
    judge_seeds = tiny.get("judge", {}).get("seeds", [])
    judged = [e for e in ("A-to-B", "A-to-C") if is_large(e)]  # judge.smk: JUDGE_EXPERIMENTS
    if judge_seeds:  # photo_loop = the main sweep's rule train; calibrated and two fold twins = judge_train
        main |= {(e, s) for e in judged for s in judge_seeds}
        expected.update(judge_train=3 * len(judged) * len(judge_seeds), twin_selection=1)
    expected.update(train=len(main))
    assert edit_reruns(work, "conf/workflow/tiny.yaml", bigger_large_model) == expected
    assert job_stats(snakemake(work, "-n")) == Counter(), "restoring the configs restores the state"


def test_report_holds_every_figure_caption(runs):
    work = runs.clean
    snakemake(work, "--report", "results/report.html")
    html = (work / "results" / "report.html").read_text()
    captions = [json.loads(f'"{c}"') for c in re.findall(r'"caption": "((?:[^"\\]|\\.)*)"', html)]
    shown = " ".join(" ".join(re.sub(r"<[^>]+>", "", c).split()) for c in captions)  # rendered RST, as text
    rules = "".join(p.read_text() for p in (REPO_ROOT / "workflow" / "rules").glob("*.smk"))
    used = set(re.findall(r"report/(\w+\.rst)", rules)) | set(re.findall(r'"(\w+\.rst)"', rules))
    assert len(used) >= 10
    tiny = yaml.safe_load((REPO_ROOT / "conf" / "workflow" / "tiny.yaml").read_text())
    if not tiny["train"]["ablation"]["clip_lens"]:  # the tiny profile makes no Table 3
        used.discard("table3_clip_len.rst")
    for name in sorted(used):
        source = (REPO_ROOT / "workflow" / "report" / name).read_text().replace("``", "")
        assert " ".join(source.split()[:5]) in shown, f"caption {name} missing from the report"
