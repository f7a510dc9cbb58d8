"""All MLflow calls of the project live here; science modules return numbers and never import mlflow.

The tracking store defaults to SQLite at `results/mlflow.db` and is overridden by the standard
`MLFLOW_TRACKING_URI`. Creating the SQLite schema is not safe when two Snakemake jobs open a fresh
store at the same instant, so the first connection (schema creation and migrations) and experiment
creation run under a file lock next to the database.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
from pathlib import Path
from typing import Any, Iterator, Mapping

from filelock import FileLock

from palpation.paths import REPO_ROOT, results_dir


def tracking_uri() -> str:
    uri = os.environ.get("MLFLOW_TRACKING_URI")
    if uri:
        return uri
    return f"sqlite:///{(results_dir() / 'mlflow.db').resolve()}"


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


@contextlib.contextmanager
def start_run(stage: str, params: Mapping[str, Any] | None = None, run_name: str | None = None,
              tags: Mapping[str, str] | None = None) -> Iterator[Any]:
    """Open an MLflow run in the experiment named after `stage`, with params and standard tags."""
    import mlflow

    uri = tracking_uri()
    lock = _lock_path(uri)
    lock.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(str(lock), timeout=120):
        mlflow.set_tracking_uri(uri)
        if mlflow.get_experiment_by_name(stage) is None:
            # artefacts beside the store, not in ./mlruns of whatever folder the job started in
            mlflow.create_experiment(stage, artifact_location=artifact_root(stage))
        mlflow.set_experiment(stage)
    all_tags = {
        "git_commit": git_commit(),
        "stage": stage,
        "profile": os.environ.get("PALPATION_PROFILE", "adhoc"),
        "snakemake_rule": os.environ.get("SNAKEMAKE_RULE", "none"),
    }
    all_tags.update(tags or {})
    with mlflow.start_run(run_name=run_name, tags=all_tags) as run:
        if params:
            flat = {k: str(v)[:500] for k, v in flatten(params).items()}
            mlflow.log_params(flat)
        yield run


def log_metrics(metrics: Mapping[str, float], step: int | None = None) -> None:
    import mlflow

    mlflow.log_metrics({k: float(v) for k, v in metrics.items()}, step=step)


def log_artifact(path: str | os.PathLike, artifact_path: str | None = None) -> None:
    import mlflow

    mlflow.log_artifact(str(path), artifact_path=artifact_path)
