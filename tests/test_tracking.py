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


def _dead_pid() -> int:
    out = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                         text=True, check=True)
    return int(out.stdout)


def test_process_gone():
    me = tracking.process_id()
    host, pid, start = me.split(":")
    assert not tracking.process_gone(me)
    assert tracking.process_gone(f"{host}:{_dead_pid()}:{start}")
    assert tracking.process_gone(f"{host}:{pid}:{float(start) + 1:.2f}")  # same pid, another process
    assert not tracking.process_gone(f"elsewhere:{_dead_pid()}:1")  # another host: unknown, left alone


def test_run_of_a_killed_process_is_marked_killed(results_tmp):
    """A run left RUNNING by a SIGKILLed job is KILLED when the next run of that experiment starts."""
    code = (
        "import os, signal\n"
        "from palpation import tracking\n"
        "with tracking.start_run('killed', params={'x': 1}, config='job'):\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    assert subprocess.run([sys.executable, "-c", code], timeout=300).returncode == -9
    import mlflow

    mlflow.set_tracking_uri(tracking.tracking_uri())
    client = mlflow.MlflowClient()
    exp = client.get_experiment_by_name("killed").experiment_id
    # a RUNNING run of a live process (this one) and one of another host stay RUNNING
    alive = client.create_run(exp, tags={"process": tracking.process_id()}).info.run_id
    remote = client.create_run(exp, tags={"process": "elsewhere:1:1"}).info.run_id
    [orphan] = [r for r in client.search_runs([exp]) if r.data.tags.get("mlflow.runName") == "killed/job"]
    assert orphan.info.status == "RUNNING"
    with tracking.start_run("killed", params={"x": 1}, config="job") as run:
        pass
    status = {r.info.run_id: r.info.status for r in client.search_runs([exp])}
    assert status[orphan.info.run_id] == "KILLED"
    assert status[alive] == status[remote] == "RUNNING"
    assert status[run.info.run_id] == "FINISHED"
    assert "gone" in client.get_run(orphan.info.run_id).data.tags["killed_reason"]


def test_rerun_of_a_job_supersedes_its_finished_run(results_tmp, monkeypatch):
    monkeypatch.setenv("SNAKEMAKE_RULE", "train")
    ids = []
    for params in ({"lr": 1}, {"lr": 2}, {"lr": 1}):
        with tracking.start_run("rerun", params=params, config="A-to-B/L5", seed=0) as run:
            ids.append(run.info.run_id)
    import mlflow

    mlflow.set_tracking_uri(tracking.tracking_uri())
    tags = {r.info.run_id: r.data.tags for r in mlflow.MlflowClient().search_runs(
        [mlflow.get_experiment_by_name("rerun").experiment_id])}
    assert tags[ids[0]]["superseded_by"] == ids[2]  # same rule, name and params: the same job
    assert "superseded_by" not in tags[ids[1]] and "superseded_by" not in tags[ids[2]]
    assert tags[ids[0]]["job_key"] == tags[ids[2]]["job_key"] != tags[ids[1]]["job_key"]
    assert tags[ids[0]]["snakemake_rule"] == "train"


def test_git_commit_override(monkeypatch):
    from palpation.tracking import git_commit

    monkeypatch.setenv("PALPATION_GIT_COMMIT", "abc123")
    assert git_commit() == "abc123"
    monkeypatch.delenv("PALPATION_GIT_COMMIT")
    assert git_commit() != "abc123"


def test_run_names_kind_span_and_linked_artefacts(results_tmp, tmp_path, monkeypatch):
    """One name scheme, the runs view as the experiment's page, the run spanning the app's work, a
    checkpoint stored once (hard link) and unchanged in MLflow when the run folder's file is rewritten."""
    import time

    import mlflow

    from palpation.io import save_text

    monkeypatch.setenv("PALPATION_PROFILE", "quick")
    checkpoint = tmp_path / "checkpoint.pt"
    save_text(checkpoint, "weights v1")
    tracking.mark_work_start()
    time.sleep(0.3)
    with tracking.start_run("names", {"x": 1}, "A-to-B/L5", seed=3) as run:
        tracking.log_artifact(checkpoint)
    inode = checkpoint.stat().st_ino
    save_text(checkpoint, "weights v2")  # a later run's atomic rewrite
    client = mlflow.MlflowClient(tracking.tracking_uri())
    got = client.get_run(run.info.run_id)
    assert got.data.tags["mlflow.runName"] == "names/A-to-B/L5/seed3"
    assert got.data.tags["launched_by"] == "hand"
    assert got.info.end_time - got.info.start_time >= 300
    exp = client.get_experiment_by_name("names")
    assert exp.tags["mlflow.experimentKind"] == "custom_model_development"
    [stored] = (results_tmp / "mlartifacts" / "names").rglob("checkpoint.pt")
    assert stored.read_text() == "weights v1" and stored.stat().st_ino == inode  # one copy on disk
    assert tracking.run_name("photos") == "photos/quick"


def test_model_logged_once_as_a_logged_model_pointing_at_its_checkpoint(results_tmp, tmp_path):
    """A trained model: one LoggedModel (the Models tab) whose checkpoint is the run's hard-linked artefact."""
    import mlflow

    from palpation.io import save_text

    checkpoint = tmp_path / "checkpoint.pt"
    save_text(checkpoint, "weights")
    with tracking.start_run("models", {"x": 1}, "A-to-B/L5", seed=0) as run:
        model_id = tracking.log_checkpoint(checkpoint, {"model": "large", "seed": 0})
    model = mlflow.MlflowClient(tracking.tracking_uri()).get_logged_model(model_id)
    assert (model.name, model.model_type, model.source_run_id) == ("models_A-to-B_L5_seed0", "palpation-stgnn",
                                                                    run.info.run_id)
    assert model.params == {"model": "large", "seed": "0"}
    assert model.tags["checkpoint"].endswith(f"{run.info.run_id}/artifacts/checkpoint.pt")
    stored = list((results_tmp / "mlartifacts").rglob("checkpoint.pt"))
    assert len(stored) == 1 and stored[0].stat().st_ino == checkpoint.stat().st_ino  # no second copy
    assert not list((results_tmp / "mlartifacts").rglob("*.pth"))
