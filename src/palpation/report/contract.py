"""The reproducibility contract: is a run's table the committed one, within what another machine may change?

    python -m palpation.report.contract check results --against docs/results/reproduce/quick
    python -m palpation.report.contract measure RUN_A RUN_B --out docs/results/contract.json

Three tiers (docs/DEVELOPING.md, "Reproducibility contract"):
1. Same host, same seed, CPU, same threads: every table byte-identical. Any difference is a bug.
2. Another host, CPU ISA or BLAS build: a table has the same rows and text; each number lies within its column's
   tolerance in docs/results/contract.json. The tolerances are measured (`measure`: twice the largest difference
   between a run and the same run made as another CPU would, rounded up to a 1-2-5 step), not guessed.
3. CPU against GPU: the twin agrees to 0.0005 px (twin.agreement); trained detectors are not held to tier 2.

`check` prints "within contract" (exit 0), or names each table, row, column and difference that breaks it
(exit 1). The tables are the results page's (compare.SOURCES), matched to the reference folder by file name.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pandas as pd

from palpation.io import save_json
from palpation.readers import read_csv, read_json
from palpation.report.compare import SOURCES

RUN_FIX = "re-run the workflow (`make reproduce`)"
MARGIN = 2.0  # a tolerance covers twice the largest difference measured: one emulated host is one sample of many
TOLERANCES = Path(__file__).resolve().parents[3] / "docs" / "results" / "contract.json"


def contract_tables(run: Path, reference: Path) -> list[tuple[str, Path, Path]]:
    """(name, run file, reference file) of every results-page table the reference folder holds."""
    out = []
    for source in SOURCES.values():
        name = Path(source.path).name
        if (reference / name).is_file():
            out.append((name, run / source.path, reference / name))
    return out


def _numeric(frame: pd.DataFrame) -> list[str]:
    return [c for c in frame.columns if pd.api.types.is_numeric_dtype(frame[c]) and not
            pd.api.types.is_bool_dtype(frame[c])]


def _keys(frame: pd.DataFrame) -> list[str]:
    """Columns that name a row: text and booleans, plus integer seeds, folds, rounds and clip lengths."""
    named = {"seed", "round", "clip_len", "fold", "seeds", "n_seeds", "trials"}
    numeric = set(_numeric(frame))
    return [c for c in frame.columns if c not in numeric or c in named]


def _row_name(frame: pd.DataFrame, i: int) -> str:
    return ", ".join(f"{k}={frame.iloc[i][k]}" for k in _keys(frame)[:3]) or f"row {i}"


def _gaps(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| per row: 0 where both are NaN, infinite where only one is."""
    return np.where(np.isnan(a) & np.isnan(b), 0.0, np.nan_to_num(np.abs(a - b), nan=math.inf))


def differences(name: str, got: pd.DataFrame, want: pd.DataFrame) -> tuple[list[str], dict[str, float]]:
    """Structural mismatches (lines) and the largest |difference| of each numeric column (NaN = NaN)."""
    if list(got.columns) != list(want.columns) or len(got) != len(want):
        return [f"{name}: columns or rows differ ({len(got)} rows {list(got.columns)} vs {len(want)} rows "
                f"{list(want.columns)})"], {}
    problems, keys = [], _keys(want)
    for key in keys:
        a, b = got[key].astype(str).to_numpy(), want[key].astype(str).to_numpy()
        for i in np.flatnonzero(a != b)[:3]:
            problems.append(f"{name} {_row_name(want, i)}: {key} is {a[i]!r}, committed {b[i]!r}")
    worst = {}
    for col in [c for c in _numeric(want) if c not in keys]:
        gaps = _gaps(got[col].to_numpy(float), want[col].to_numpy(float))
        worst[col] = float(gaps.max()) if len(gaps) else 0.0
    return problems, worst


def check(run: Path, reference: Path, tolerances: dict) -> list[str]:
    """Every breach of the contract by the tables of `run` (a results root) against `reference` ([]: none)."""
    tables = contract_tables(run, reference)
    if not tables:
        names = ", ".join(sorted(Path(s.path).name for s in SOURCES.values()))
        raise ValueError(f"{reference}: holds none of the results page's tables ({names}); pass the folder of "
                         "committed tables, e.g. --against docs/results/reproduce/quick")
    lines = []
    for name, got_path, want_path in tables:
        if not got_path.is_file():
            lines.append(f"{name}: {got_path} is missing; {RUN_FIX}")
            continue
        if got_path.read_bytes() == want_path.read_bytes():
            continue  # tier 1
        got = read_csv(got_path, fix=RUN_FIX, what="run table", rows=False)
        want = read_csv(want_path, fix="restore it with `git checkout`", what="committed table", rows=False)
        problems, worst = differences(name, got, want)
        lines += problems
        allowed = tolerances.get(name, {})
        for col, delta in worst.items():
            tol = float(allowed.get(col, 0.0))
            if delta > tol:
                a, b = got[col].to_numpy(float), want[col].to_numpy(float)
                i = int(np.argmax(_gaps(a, b)))
                lines.append(f"{name} {_row_name(want, i)}: {col} {a[i]:.6g} vs committed {b[i]:.6g} "
                             f"(|diff| {abs(a[i] - b[i]):.3g} > tolerance {tol:g})")
    return lines


def step_up(x: float) -> float:
    """The smallest 1-2-5 step (..., 0.001, 0.002, 0.005, 0.01, ...) at or above x; 0 stays 0."""
    if x <= 0:
        return 0.0
    if not math.isfinite(x):
        return math.inf
    exp = math.floor(math.log10(x))
    for mant in (1, 2, 5, 10):
        step = mant * 10.0 ** exp
        if step >= x * (1 - 1e-12):
            return float(f"{step:.12g}")
    return 10.0 ** (exp + 1)


def measure(run_a: Path, run_b: Path, reference: Path) -> dict:
    """Per table and column: the largest difference between two runs of the same code (one made as another CPU
    would), and the tolerance: MARGIN times it, rounded up to a 1-2-5 step (step_up)."""
    out = {}
    for name, a_path, _ in contract_tables(run_a, reference):
        b_path = run_b / a_path.relative_to(run_a)
        problems, worst = differences(name, read_csv(a_path, fix=RUN_FIX, what="run table", rows=False),
                                      read_csv(b_path, fix=RUN_FIX, what="run table", rows=False))
        if problems:
            raise ValueError(f"{problems[0]}: the two runs differ in structure, not rounding; compare runs of one commit")
        out[name] = {col: {"measured": delta, "tolerance": step_up(MARGIN * delta)} for col, delta in worst.items()}
    return out


def load_tolerances(path: Path) -> dict[str, dict[str, float]]:
    record = read_json(path, fix="restore docs/results/contract.json with `git checkout`", what="contract tolerances",
                       kind=dict, keys=("how", "tables"))
    return {name: {col: v["tolerance"] for col, v in cols.items()} for name, cols in record["tables"].items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    chk = sub.add_parser("check", help="compare a run's tables with the committed ones under the contract")
    chk.add_argument("results", type=Path, help="the run's results root (e.g. results)")
    chk.add_argument("--against", type=Path, default=Path("docs/results/reproduce/quick"), help="committed tables")
    chk.add_argument("--tolerances", type=Path, default=TOLERANCES, help="measured tolerances (contract.json)")
    mea = sub.add_parser("measure", help="measure the tolerances from two runs of one commit")
    mea.add_argument("run_a", type=Path)
    mea.add_argument("run_b", type=Path, help="the same run made as another CPU would (docs/DEVELOPING.md)")
    mea.add_argument("--against", type=Path, default=Path("docs/results/reproduce/quick"), help="which tables (by name)")
    mea.add_argument("--how", required=True, help="how run_b differs from run_a (kept in the record)")
    mea.add_argument("--out", type=Path, default=TOLERANCES)
    args = parser.parse_args(argv)
    try:
        if args.command == "measure":
            tables = measure(args.run_a, args.run_b, args.against)
            save_json(args.out, {"how": args.how, "tables": tables})
            for name, cols in tables.items():
                moved = {c: v["measured"] for c, v in cols.items() if v["measured"] > 0}
                print(f"{name}: {'identical' if not moved else moved}")
            return 0
        lines = check(args.results, args.against, load_tolerances(args.tolerances))
    except (ValueError, OSError) as exc:
        print(f"error: {exc}")
        return 2
    if lines:
        print("\n".join(["outside contract:"] + lines))
        return 1
    print(f"within contract ({len(contract_tables(args.results, args.against))} tables against {args.against})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
