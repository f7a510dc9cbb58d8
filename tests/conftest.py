"""Shared test fixtures: every test writes its outputs and MLflow store into a temp folder."""

import pytest


@pytest.fixture
def results_tmp(tmp_path, monkeypatch):
    """Point results_dir() and the MLflow store at a fresh temp folder."""
    monkeypatch.setenv("PALPATION_RESULTS", str(tmp_path))
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    return tmp_path
