"""All MLflow calls of the project live here; science modules return numbers and never import mlflow.

The tracking store defaults to SQLite at `results/mlflow.db` and is overridden by the standard
`MLFLOW_TRACKING_URI`. Creating the SQLite schema is not safe when two Snakemake jobs open a fresh
store at the same instant, so the first connection (schema creation and migrations) and experiment
creation run under a file lock next to the database.

A job killed hard (SIGKILL, a lost node) leaves its run RUNNING. Every run records the process that
owns it (`process` tag: host, pid, start time), and `start_run` marks KILLED any RUNNING run of the same
experiment whose process on this host is gone. It also tags earlier FINISHED runs of the same job
(`job_key`: stage, Snakemake rule, run name and params) `superseded_by` the new run, since the new run
overwrites their outputs; "the current runs" are the FINISHED ones without that tag.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import json
import os
import subprocess
import time
import urllib.parse
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping

from filelock import FileLock

from palpation.io import hard_link
from palpation.paths import REPO_ROOT, results_dir
from palpation.process import process_gone, process_id


def tracking_uri() -> str:
    uri = os.environ.get("MLFLOW_TRACKING_URI")
    if uri:
        return uri
    return f"sqlite:///{(results_dir() / 'mlflow.db').resolve()}"


def check_store() -> None:
    """Fail at app start, not after the work, when MLflow is not installed or the SQLite store cannot be used: not
    a database, or the file or its folder not writable. Other stores (a server) are left to MLflow."""
    if importlib.util.find_spec("mlflow") is None:  # a bare machine (a lent GPU) may lack it: say so before the work
        raise ValueError("track=true logs to MLflow, which this Python cannot import; install the lock's "
                         "mlflow (pip install mlflow==3.17.2) or pass track=false")
    uri = tracking_uri()
    if not uri.startswith("sqlite:///"):
        return
    db = Path(uri[len("sqlite:///"):])
    origin = "MLFLOW_TRACKING_URI" if os.environ.get("MLFLOW_TRACKING_URI") else "the default store"
    fix = f"move or delete it, or set MLFLOW_TRACKING_URI to a usable store ({origin} is {uri})"
    folder = next((p for p in (db, *db.parents) if p.exists()), db.anchor)
    if not db.exists():
        if not os.access(folder, os.W_OK):
            raise PermissionError(f"MLflow store {db} cannot be created: {folder} is not writable; {fix}")
        return
    if not os.access(db, os.W_OK) or not os.access(db.parent, os.W_OK):
        raise PermissionError(f"MLflow store {db} (or its folder) is not writable; {fix}")
    import sqlite3

    try:
        with contextlib.closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as con:
            con.execute("select count(*) from sqlite_master").fetchone()
    except sqlite3.DatabaseError as exc:
        raise ValueError(f"MLflow store {db} is not a usable SQLite database ({exc}); {fix}") from None


def artifact_root(stage: str) -> str:
    return (results_dir() / "mlartifacts" / stage).resolve().as_uri()


def _lock_path(uri: str) -> Path:
    if uri.startswith("sqlite:///"):
        db = Path(uri[len("sqlite:///"):])
        return db.with_name(db.name + ".lock")
    return results_dir() / ".mlflow.lock"


def git_commit() -> str:
    """HEAD of the checkout, or $PALPATION_GIT_COMMIT where the tree was copied without its history."""
    if os.environ.get("PALPATION_GIT_COMMIT"):
        return os.environ["PALPATION_GIT_COMMIT"]
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True,
                             text=True, timeout=10)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def flatten(cfg: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested mapping -> {"a.b.c": value}, the form MLflow params take."""
    flat: dict[str, Any] = {}
    for key, value in cfg.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def job_key(stage: str, rule: str, run_name: str | None, params: Mapping[str, Any]) -> str:
    """What makes two runs the same job: a rerun of it gets the same key."""
    blob = json.dumps([stage, rule, run_name, params], sort_keys=True, default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:16]


def close_orphans(client: Any, experiment_id: str, by: str = "") -> list[str]:
    """Mark KILLED the RUNNING runs of an experiment whose process is gone; returns their ids."""
    killed = []
    for run in client.search_runs([experiment_id], filter_string="attributes.status = 'RUNNING'"):
        owner = run.data.tags.get("process", "")
        if owner and process_gone(owner):
            client.set_tag(run.info.run_id, "killed_reason", f"process {owner} gone; found by {by or 'a new run'}")
            client.set_terminated(run.info.run_id, status="KILLED")
            killed.append(run.info.run_id)
    return killed


def supersede(client: Any, experiment_id: str, key: str, new_run_id: str) -> list[str]:
    """Tag the earlier FINISHED runs of job `key` superseded by `new_run_id`; returns their ids."""
    old = client.search_runs([experiment_id],
                             filter_string=f"tags.job_key = '{key}' and attributes.status = 'FINISHED'")
    ids = [r.info.run_id for r in old if r.info.run_id != new_run_id and "superseded_by" not in r.data.tags]
    for run_id in ids:
        client.set_tag(run_id, "superseded_by", new_run_id)
    return ids


_work_started: float | None = None


def _use_store(uri: str) -> None:
    """mlflow.set_tracking_uri, without the MLFLOW_TRACKING_URI it exports: a later run of this process
    with another results folder must not inherit the store as if the user had set it."""
    import mlflow

    user = os.environ.get("MLFLOW_TRACKING_URI")
    mlflow.set_tracking_uri(uri)
    if user is None:
        os.environ.pop("MLFLOW_TRACKING_URI", None)


def mark_work_start() -> None:
    """Called by `config_check.app_main` before an app's work: the app's run starts here, even when
    the app opens it after the work (a run then spans what it tracks, not the last 50 ms)."""
    global _work_started
    _work_started = time.time()


def run_name(stage: str, config: str | None = None, seed: int | str | None = None) -> str:
    """One naming scheme for every stage: `<stage>/<config>[/seed<seed>]`; config defaults to the profile."""
    parts = [stage, config or os.environ.get("PALPATION_PROFILE", "adhoc")]
    if seed is not None:
        parts.append(f"seed{seed}")
    return "/".join(parts)


def _sweep_tags() -> dict[str, str]:
    """Where a run was launched from: the workflow (a Snakemake rule) or by hand, and which sweep."""
    tags = {"launched_by": "snakemake" if os.environ.get("SNAKEMAKE_RULE") else "hand"}
    try:
        from hydra.core.hydra_config import HydraConfig

        hc = HydraConfig.get()
    except (ImportError, ValueError):  # not inside a Hydra job
        return tags
    if str(hc.mode) == "RunMode.MULTIRUN":
        tags.update({"hydra_sweep": str(hc.sweep.dir), "hydra_job": str(hc.job.num)})
    return tags


def experiment_name(stage: str, tags: Mapping[str, str]) -> str:
    """Hand-launched Hydra sweeps go to `<stage>-sweeps`, apart from the workflow's runs of `stage`."""
    return f"{stage}-sweeps" if tags["launched_by"] == "hand" and "hydra_sweep" in tags else stage


@contextlib.contextmanager
def start_run(stage: str, params: Mapping[str, Any] | None = None, config: str | None = None,
              tags: Mapping[str, str] | None = None, seed: int | str | None = None) -> Iterator[Any]:
    """Open an MLflow run named `run_name(stage, config, seed)` with params and standard tags.

    The run starts when the app's work started (`mark_work_start`) if that is earlier than now."""
    import mlflow

    uri = tracking_uri()
    lock = _lock_path(uri)
    lock.parent.mkdir(parents=True, exist_ok=True)
    flat = {k: str(v)[:500] for k, v in flatten(params or {}).items()}
    rule = os.environ.get("SNAKEMAKE_RULE", "none")
    name = run_name(stage, config, seed)
    key = job_key(stage, rule, name, flat)
    where = _sweep_tags()
    experiment_label = experiment_name(stage, where)
    with FileLock(str(lock), timeout=120):
        _use_store(uri)
        if mlflow.get_experiment_by_name(experiment_label) is None:
            # artefacts beside the store, not in ./mlruns of whatever folder the job started in; the
            # kind tag makes MLflow 3's UI open the runs view instead of the GenAI traces page
            mlflow.create_experiment(experiment_label, artifact_location=artifact_root(experiment_label),
                                     tags={"mlflow.experimentKind": "custom_model_development"})
        experiment = mlflow.set_experiment(experiment_label)
        client = mlflow.MlflowClient()
        close_orphans(client, experiment.experiment_id, by=process_id())
    all_tags = {
        "git_commit": git_commit(),
        "stage": stage,
        "profile": os.environ.get("PALPATION_PROFILE", "adhoc"),
        "snakemake_rule": rule,
        "job_key": key,
        "process": process_id(),
        "mlflow.runName": name,
        **where,
    }
    all_tags.update({k: str(v) for k, v in (tags or {}).items()})
    started = min(_work_started or time.time(), time.time())
    created = client.create_run(experiment.experiment_id, start_time=int(started * 1000), tags=all_tags,
                                run_name=name)
    with mlflow.start_run(run_id=created.info.run_id) as run:
        if flat:
            mlflow.log_params(flat)
        with FileLock(str(lock), timeout=120):
            supersede(client, experiment.experiment_id, key, run.info.run_id)
        yield run


def log_metrics(metrics: Mapping[str, float], step: int | None = None) -> None:
    import mlflow

    mlflow.log_metrics({k: float(v) for k, v in metrics.items()}, step=step)


def log_metric_history(steps: Iterable[tuple[Mapping[str, float], int]]) -> None:
    """Log (metrics, step) pairs recorded earlier into the active run, in batches (one call per step
    would be one store transaction each)."""
    import mlflow
    from mlflow.entities import Metric

    now = int(time.time() * 1000)
    rows = [Metric(k, float(v), now, step) for metrics, step in steps for k, v in metrics.items()]
    run_id = mlflow.active_run().info.run_id
    for s in range(0, len(rows), 1000):  # MLflow's limit per log_batch
        mlflow.MlflowClient().log_batch(run_id, metrics=rows[s:s + 1000])


def log_artifact(path: str | os.PathLike, artifact_path: str | None = None) -> None:
    """Log a file of the active run. On a local artefact store on the same file system the file is
    hard-linked, not copied: a checkpoint then lives on disk once, in the run folder and in MLflow, and
    an atomic rewrite by a later run (a new inode) leaves the older run's artefact as it was."""
    import mlflow

    src = Path(path)
    uri = mlflow.get_artifact_uri(artifact_path)
    if uri.startswith("file://"):
        dest = Path(urllib.parse.unquote(urllib.parse.urlparse(uri).path)) / src.name
        dest.parent.mkdir(parents=True, exist_ok=True)
        if hard_link(src, dest):
            return
    mlflow.log_artifact(str(src), artifact_path=artifact_path)  # another file system, or links not allowed: copy


def log_checkpoint(path: str | os.PathLike, params: Mapping[str, Any] | None = None) -> str:
    """Log a trained model once: its checkpoint as the run's artefact (hard-linked, `log_artifact`) and an
    MLflow 3 LoggedModel of type `palpation-stgnn` (the Models tab) that points at it instead of a copy.
    Returns the model id.

    Not `mlflow.pytorch.log_model`, measured on the large ST-GNN (MLflow 3.17.2, 2-core CPU): its default
    format, pt2, cannot export the model (`forward` takes a PyG batch, the input example must be tensors);
    the pickle format writes a second 4.22 MB copy of the weights per run without the normalisation
    statistics and rest layout that scoring needs (checkpoint.pt carries them), and inferring its pip
    requirements took 52.8 s per run (0.7 s with them given)."""
    import mlflow

    path = Path(path)
    log_artifact(path)
    run = mlflow.active_run()
    name = run.data.tags.get("mlflow.runName", path.parent.name).replace("/", "_")
    model = mlflow.create_external_model(
        name=name, model_type="palpation-stgnn", params={k: str(v) for k, v in (params or {}).items()},
        tags={"checkpoint": f"{mlflow.get_artifact_uri()}/{path.name}"})
    return model.model_id


def log_figure(stem: str | os.PathLike, artifact_path: str = "figures") -> None:
    """Log a figure saved by `io.save_figure` (its .png and .pdf) of the active run."""
    for suffix in (".png", ".pdf"):
        path = Path(f"{stem}{suffix}")
        if path.exists():
            log_artifact(path, artifact_path)
