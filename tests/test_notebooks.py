"""The results notebook runs headless on whatever results/ holds and never writes to it."""

import nbformat
from nbclient import NotebookClient

from palpation.paths import REPO_ROOT


def test_results_notebook_executes(tmp_path, monkeypatch):
    results = tmp_path / "results"
    data = results / "data"
    data.mkdir(parents=True)
    (data / "summary.csv").write_text("dataset,trials,frames\nsilicone,10,160\n")
    monkeypatch.setenv("PALPATION_RESULTS", str(results))
    before = sorted(p.name for p in results.rglob("*"))
    nb = nbformat.read(REPO_ROOT / "notebooks" / "results_overview.ipynb", as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(REPO_ROOT / "notebooks")}}).execute()
    outputs = "".join(o.get("text", "") for c in nb.cells for o in c.get("outputs", []))
    assert "calibration/calibration.csv: not produced yet" in outputs
    assert sorted(p.name for p in results.rglob("*")) == before
