"""The MLflow helper: default sqlite store under results/, env override, safe concurrent first use."""

import subprocess
import sys

from palpation import tracking


def test_default_uri_is_sqlite_under_results(results_tmp):
    assert tracking.tracking_uri() == f"sqlite:///{(results_tmp / 'mlflow.db').resolve()}"


def test_env_overrides_uri(monkeypatch, tmp_path):
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/other.db")
    assert tracking.tracking_uri().endswith("other.db")


def test_flatten_nested_config():
    assert tracking.flatten({"a": {"b": 1, "c": {"d": 2}}, "e": 3}) == {"a.b": 1, "a.c.d": 2, "e": 3}


def test_two_processes_create_the_store_together(results_tmp):
    """Two jobs opening a fresh store at once must both succeed and both runs must be recorded."""
    code = (
        "from palpation import tracking\n"
        "with tracking.start_run('concurrency', params={'x': 1}):\n"
        "    tracking.log_metrics({'m': 1.0})\n"
    )
    procs = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(2)]
    assert [p.wait(timeout=300) for p in procs] == [0, 0]
    import mlflow

    mlflow.set_tracking_uri(tracking.tracking_uri())
    runs = mlflow.search_runs(experiment_names=["concurrency"])
    assert len(runs) == 2
    assert set(runs["tags.git_commit"]) != {""}


def test_artifacts_go_under_results_not_cwd(results_tmp, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    art = tmp_path / "a.txt"
    art.write_text("x")
    with tracking.start_run("artefacts"):
        tracking.log_artifact(art)
    assert not (tmp_path / "mlruns").exists()
    assert list((results_tmp / "mlartifacts" / "artefacts").rglob("a.txt"))


def test_git_commit_override(monkeypatch):
    from palpation.tracking import git_commit

    monkeypatch.setenv("PALPATION_GIT_COMMIT", "abc123")
    assert git_commit() == "abc123"
    monkeypatch.delenv("PALPATION_GIT_COMMIT")
    assert git_commit() != "abc123"
