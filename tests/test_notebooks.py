"""Every notebook runs headless on whatever results/ holds, reports only current runs, never writes there."""

import json

import nbformat
import pytest
from nbclient import NotebookClient

from palpation import tracking
from palpation.paths import REPO_ROOT

NOTEBOOKS = sorted((REPO_ROOT / "notebooks").glob("*.ipynb"))


def _outputs(nb) -> str:
    texts = []
    for cell in nb.cells:
        for out in cell.get("outputs", []):
            texts.append(out.get("text", "") + out.get("data", {}).get("text/plain", ""))
    return "\n".join(texts)


@pytest.fixture
def small_results(tmp_path, monkeypatch):
    """A results folder with a few stages done and an MLflow store holding one superseded rerun."""
    results = tmp_path / "results"
    monkeypatch.setenv("PALPATION_RESULTS", str(results))
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)  # mlflow.set_tracking_uri of earlier tests sets it
    (results / "data" / "silicone").mkdir(parents=True)
    (results / "data" / "summary.csv").write_text("dataset,trials,frames\nsilicone,10,160\n")
    (results / "data" / "silicone" / "label_agreement.json").write_text(json.dumps(
        {"mean_agreement": 0.995, "min_agreement": 0.98, "n_states": 160, "per_state": []}))
    for _ in range(2):  # the same job twice: the first run is superseded
        with tracking.start_run("photos", {"x": 1}):
            pass
    return results


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, small_results):
    before = sorted(str(p) for p in small_results.rglob("*") if "mlflow.db" not in p.name)
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(path.parent)}}).execute()
    text = _outputs(nb)
    assert "None" not in text
    assert sorted(str(p) for p in small_results.rglob("*") if "mlflow.db" not in p.name) == before
    if path.stem == "results_overview":
        assert "calibration/calibration.csv: not produced yet" in text
        assert "agreement mean 99.50 %, min 98.00 % over 160 states" in text
        assert "1 superseded and 0 unfinished runs not counted" in text
        assert text.count("silicone") == 1  # the summary table shown once, not twice
