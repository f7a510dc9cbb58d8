"""The reproducibility contract's check and measurement on toy tables (report.contract)."""

import json

import pandas as pd
import pytest

from palpation.report import contract

SWEEP = pd.DataFrame({"config": ["A-to-B", "C-to-B"], "seed": [0, 3], "auroc": [0.71, 0.5207], "ap": [0.3, 0.2],
                      "fg_iou": [0.1, float("nan")], "bg_iou": [0.9, 0.8], "chance": [0.11, 0.11]})


def _run(root, frame):
    path = root / "train" / "report" / "seed_sweep.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(path, index=False)
    return root


@pytest.fixture
def reference(tmp_path):
    ref = tmp_path / "committed"
    ref.mkdir()
    SWEEP.to_csv(ref / "seed_sweep.csv", index=False)
    return ref


def test_byte_identical_tables_are_within_contract(tmp_path, reference, capsys):
    run = _run(tmp_path / "run", SWEEP)
    tol = tmp_path / "tol.json"
    tol.write_text(json.dumps({"how": "toy", "tables": {}}))
    assert contract.main(["check", str(run), "--against", str(reference), "--tolerances", str(tol)]) == 0
    assert capsys.readouterr().out.startswith("within contract (1 tables")


def test_a_difference_within_its_measured_tolerance_passes_and_one_beyond_is_named(tmp_path, reference):
    moved = SWEEP.copy()
    moved.loc[1, "auroc"] = 0.5170  # the cross-host difference the contract has to allow or name
    run = _run(tmp_path / "run", moved)
    assert contract.check(run, reference, {"seed_sweep.csv": {"auroc": 0.005}}) == []
    lines = contract.check(run, reference, {"seed_sweep.csv": {"auroc": 0.002}})
    assert lines == ["seed_sweep.csv config=C-to-B, seed=3: auroc 0.517 vs committed 0.5207 (|diff| 0.0037 > "
                     "tolerance 0.002)"]


def test_a_nan_that_appears_or_a_changed_row_breaks_the_contract(tmp_path, reference):
    moved = SWEEP.copy()
    moved.loc[0, "fg_iou"] = float("nan")
    assert "fg_iou nan vs committed 0.1" in contract.check(_run(tmp_path / "a", moved), reference, {})[0]
    renamed = SWEEP.copy()
    renamed.loc[1, "config"] = "A-to-C"
    assert contract.check(_run(tmp_path / "b", renamed), reference, {"seed_sweep.csv": {"auroc": 1.0}}) == [
        "seed_sweep.csv config=C-to-B, seed=3: config is 'A-to-C', committed 'C-to-B'"]
    assert "columns or rows differ" in contract.check(_run(tmp_path / "c", SWEEP.iloc[:1]), reference, {})[0]


def test_a_missing_run_table_or_an_empty_reference_is_one_line(tmp_path, reference):
    assert contract.check(tmp_path / "nothing", reference, {}) == [
        f"seed_sweep.csv: {tmp_path / 'nothing' / 'train/report/seed_sweep.csv'} is missing; re-run the workflow "
        "(`make reproduce`)"]
    with pytest.raises(ValueError, match="holds none of the results page's tables"):
        contract.check(tmp_path, tmp_path / "empty", {})


def test_measure_takes_twice_the_largest_difference_up_to_a_1_2_5_step(tmp_path, reference):
    a = _run(tmp_path / "a", SWEEP)
    moved = SWEEP.copy()
    moved.loc[1, "auroc"] = 0.5170
    b = _run(tmp_path / "b", moved)
    cols = contract.measure(a, b, reference)["seed_sweep.csv"]
    assert cols["auroc"]["measured"] == pytest.approx(0.0037) and cols["auroc"]["tolerance"] == 0.01  # 2 x, 1-2-5
    assert cols["ap"] == {"measured": 0.0, "tolerance": 0.0}
    assert [contract.step_up(x) for x in (0.0, 0.001, 0.0011, 0.003, 0.0051, 7.0)] == [0.0, 0.001, 0.002, 0.005,
                                                                                        0.01, 10.0]


def test_the_committed_reference_and_tolerances_agree_with_the_results_page(tmp_path):
    """docs/results/reproduce/quick holds results-page tables only, each with measured tolerances, and is within
    the contract against itself laid out as a results root."""
    reference = contract.TOLERANCES.parent / "reproduce" / "quick"
    names = {p.name for p in reference.glob("*.csv")}
    assert names and names == {name for name, _, _ in contract.contract_tables(reference, reference)}
    tolerances = contract.load_tolerances(contract.TOLERANCES)
    assert set(tolerances) == names
    for _, path, ref in contract.contract_tables(tmp_path, reference):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(ref.read_bytes())
    assert contract.check(tmp_path, reference, tolerances) == []
