"""Disk full, read-only results, a broken MLflow store: named at once, nothing half-written left."""

import errno
import json
import tempfile

import numpy as np
import pytest

from palpation import io, tracking
from palpation.config_check import app_main


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir())


def test_disk_full_while_writing_an_npz(tmp_path, monkeypatch, fault):
    """ENOSPC inside np.savez (disk full)"""
    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", full)
    target = tmp_path / "scores.npz"
    with fault(OSError, str(target), "No space left on device", "free space"):
        io.save_npz(target, probs=np.zeros(3))
    assert _leftovers(tmp_path) == []  # neither the file nor its temporary


def test_disk_full_while_writing_json(tmp_path, monkeypatch, fault):
    """ENOSPC while a metrics.json is written"""
    real = type(tmp_path).write_text

    def full(self, *args, **kwargs):
        real(self, "{")  # a partial write, then the error
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(type(tmp_path), "write_text", full)
    target = tmp_path / "metrics.json"
    with fault(OSError, str(target), "free space"):
        io.save_json(target, {"ap": 0.5})
    assert _leftovers(tmp_path) == []


def test_read_only_results_dir(tmp_path, monkeypatch, fault):
    """a read-only results folder (EROFS on creating the temporary)"""
    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    target = tmp_path / "train" / "checkpoint.pt"
    with fault(OSError, str(target), "read-only", "PALPATION_RESULTS"):
        io.save_bytes(target, b"x")


def test_results_dir_not_writable(tmp_path, monkeypatch, fault):
    """a results folder owned by someone else (EACCES)"""
    def denied(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", denied)
    target = tmp_path / "report.md"
    with fault(PermissionError, str(target), "make the folder writable"):
        io.save_text(target, "x")


def test_nan_metric_is_strict_json(tmp_path):
    """metrics with NaN: null in the file, listed under `non_finite` (never a bare NaN)"""
    target = tmp_path / "metrics.json"
    io.save_json(target, {"test": {"auroc": float("nan"), "ap": np.float32(0.5)}, "hist": [np.inf, 1.0]})

    def refuse(const):
        raise ValueError(f"bare {const} in {target}")

    data = json.loads(target.read_text(), parse_constant=refuse)
    assert data["test"] == {"auroc": None, "ap": 0.5} and data["hist"] == [None, 1.0]
    assert data["non_finite"] == ["test.auroc", "hist[0]"]


def test_corrupt_mlflow_store(tmp_path, monkeypatch, fault):
    """results/mlflow.db that is not a database"""
    monkeypatch.setenv("PALPATION_RESULTS", str(tmp_path))
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    (tmp_path / "mlflow.db").write_bytes(b"this is not sqlite" * 100)
    with fault(ValueError, str(tmp_path / "mlflow.db"), "not a usable SQLite database", "MLFLOW_TRACKING_URI"):
        tracking.check_store()


def test_unwritable_mlflow_store(tmp_path, monkeypatch, fault):
    """MLFLOW_TRACKING_URI naming a store in a folder without write access"""
    db = tmp_path / "store" / "mlflow.db"
    db.parent.mkdir()
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{db}")
    real = tracking.os.access
    monkeypatch.setattr(tracking.os, "access", lambda p, mode: False if str(p) == str(db.parent) else real(p, mode))
    with fault(PermissionError, str(db), "cannot be created", "MLFLOW_TRACKING_URI"):
        tracking.check_store()


def test_app_checks_the_store_before_any_work(tmp_path, monkeypatch, fault):
    """a tracked app with a corrupt store fails at start, not after the computation"""
    from omegaconf import OmegaConf

    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path / 'mlflow.db'}")
    (tmp_path / "mlflow.db").write_bytes(b"\0" * 4096 + b"garbage")
    ran = []
    with fault(SystemExit, "meat: error: MLflow store", "mlflow.db", "MLFLOW_TRACKING_URI"):
        app_main("meat")(ran.append)(OmegaConf.create({"track": True}))
    assert ran == []
    app_main("meat")(ran.append)(OmegaConf.create({"track": False}))  # untracked: the store is not needed
    assert len(ran) == 1


def test_app_without_mlflow_fails_before_any_work(tmp_path, monkeypatch, fault):
    """a tracked app on a machine whose Python lacks mlflow (a bare GPU host): one line at start, not a traceback
    after the computation; track=false still runs"""
    from omegaconf import OmegaConf

    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path / 'mlflow.db'}")
    real = tracking.importlib.util.find_spec
    monkeypatch.setattr(tracking.importlib.util, "find_spec", lambda name, *a: None if name == "mlflow" else real(name, *a))
    ran = []
    with fault(SystemExit, "simulate: error: track=true logs to MLflow", "pip install mlflow==3.17.2", "track=false"):
        app_main("simulate")(ran.append)(OmegaConf.create({"track": True}))
    assert ran == []
    app_main("simulate")(ran.append)(OmegaConf.create({"track": False}))
    assert len(ran) == 1


def test_store_check_accepts_a_fresh_and_a_real_store(tmp_path, monkeypatch):
    import sqlite3

    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path / 'new' / 'mlflow.db'}")
    tracking.check_store()  # does not exist yet: created by the first run
    db = tmp_path / "mlflow.db"
    sqlite3.connect(db).execute("create table t (x)").connection.close()
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{db}")
    tracking.check_store()


def test_killed_job_run_is_marked_killed():
    """the MLflow run of a job killed hard is closed KILLED by the rerun's start_run"""
    class Run:
        def __init__(self, owner):
            self.info = type("I", (), {"run_id": owner})()
            self.data = type("D", (), {"tags": {"process": owner}})()

    class Client:
        def __init__(self):
            self.closed = {}

        def search_runs(self, ids, filter_string):
            return [Run(f"{tracking.process_id().split(':')[0]}:999999999:1"), Run(tracking.process_id())]

        def set_tag(self, *args):
            pass

        def set_terminated(self, run_id, status):
            self.closed[run_id] = status

    client = Client()
    killed = tracking.close_orphans(client, "0")
    assert list(client.closed.values()) == ["KILLED"] and killed == list(client.closed)


@pytest.mark.parametrize("name", ["checkpoint.pt", "metrics.json"])
def test_stale_temporary_of_a_killed_writer_is_removed(tmp_path, name):
    """a SIGKILLed writer's temporary is deleted by the next write of the same path"""
    dead = tmp_path / f".{name}.{io._HOST}.999999999.abc"
    dead.write_text("half")
    io.save_text(tmp_path / name, "whole")
    assert _leftovers(tmp_path) == [name]
