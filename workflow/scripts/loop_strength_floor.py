"""The strength floor of the loop's verdict (loop.method.min_strength_steps) scored on saved generative self-test
records, without re-running the loop.

    python workflow/scripts/loop_strength_floor.py OUT_CSV RECORD.csv [RECORD.csv ...] [--floor 0.1]

For every effect a run named (surface contact aside: it is the base of the others), its fitted strength in nominal
steps (loop.effects.strength) from the record's params_fitted, and for an injected one its true strength. Prints, for
the floor: injected effects the floor would take out (the harm), spurious ones it would take out, and the runs whose
named set becomes the exact one. An effect whose parameters the record does not hold is left out (older records
named some effects without their parameters). OUT_CSV: record, seed, run, effect, injected, outside,
strength_fitted, strength_true.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pandas as pd

from palpation.loop.effects import EFFECTS, strength
from palpation.report.loop_numbers import selftest_runs


def scored(path: Path, floor: float) -> tuple[list[dict], tuple[int, int, int]]:
    """A record's rows (every named effect but surface contact, whose parameters the record holds) and its in-list
    runs: exact as recorded, exact once the effects below `floor` are taken out, in all. The runs are read as the
    docs' numbers read them (report.loop_numbers.selftest_runs)."""
    rows, before, after, n = [], 0, 0, 0
    for r in selftest_runs(path.parent, path.name):
        fitted, true = json.loads(r["params_fitted"]), json.loads(r["params_true"])
        named = [e for e in str(r["effects_named"]).split("+") if e in r["named"]]  # in the record's order
        judged = [e for e in named if e != "surface_contact" and all(name in fitted for name in EFFECTS[e].params)]
        for e in judged:
            rows.append({"record": path.name, "seed": r["seed"], "run": r["run"], "effect": e,
                         "injected": e in r["injected"], "outside": r["unlisted"],
                         "strength_fitted": round(strength(e, fitted), 4),
                         "strength_true": round(strength(e, true), 4) if e in r["injected"] else None})
        if not r["unlisted"]:
            kept = set(named) - {e for e in judged if strength(e, fitted) < floor}
            before, after, n = before + (set(named) == r["injected"]), after + (kept == r["injected"]), n + 1
    return rows, (before, after, n)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("records", type=Path, nargs="+")
    ap.add_argument("--floor", type=float, default=0.1, help="nominal steps (loop.method.min_strength_steps)")
    args = ap.parse_args()
    records = {path: scored(path, args.floor) for path in args.records}
    table = pd.DataFrame([row for rows, _ in records.values() for row in rows])
    table.to_csv(args.out, index=False)
    below = table[table.strength_fitted < args.floor]
    true = table[table.injected]
    print(f"floor {args.floor} nominal steps over {len(args.records)} records: injected effects named "
          f"{len(true)}, smallest fitted {true.strength_fitted.min():.3f} steps, taken out "
          f"{int(below.injected.sum())}; spurious named {int((~table.injected).sum())}, taken out "
          f"{int((~below.injected).sum())}")
    for path, (_, (before, after, n)) in records.items():
        print(f"  {path.name}: exact in-list {before} -> {after} of {n}")


if __name__ == "__main__":
    main()
