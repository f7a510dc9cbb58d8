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

VERDICTS = ("none", "", "unexplained")


def effects_of(text: str) -> list[str]:
    """The in-list effects of a '+'-joined record field."""
    return [e for e in str(text).split("+") if e not in VERDICTS and not e.startswith("unlisted:")]


def rows_of(path: Path) -> list[dict]:
    table = pd.read_csv(path).fillna("")
    rows = []
    for r in table.itertuples():
        injected, fitted, true = set(effects_of(r.effects_injected)), json.loads(r.params_fitted), json.loads(r.params_true)
        for e in effects_of(r.effects_named):
            if e == "surface_contact" or not all(n in fitted for n in EFFECTS[e].params):
                continue
            rows.append({"record": path.name, "seed": r.seed, "run": r.run, "effect": e, "injected": e in injected,
                         "outside": "unlisted:" in r.effects_injected,
                         "strength_fitted": round(strength(e, fitted), 4),
                         "strength_true": round(strength(e, true), 4) if e in injected else None})
    return rows


def exact_after(path: Path, floor: float) -> tuple[int, int, int]:
    """In-list runs of a record: exact as recorded, exact once the effects below `floor` are taken out, in all."""
    table = pd.read_csv(path).fillna("")
    table = table[~table.effects_injected.str.contains("unlisted:")]
    before = after = 0
    for r in table.itertuples():
        injected, fitted, named = set(effects_of(r.effects_injected)), json.loads(r.params_fitted), effects_of(r.effects_named)
        kept = {e for e in named if e == "surface_contact" or not all(n in fitted for n in EFFECTS[e].params)
                or strength(e, fitted) >= floor}
        before += set(named) == injected
        after += kept == injected
    return before, after, len(table)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("records", type=Path, nargs="+")
    ap.add_argument("--floor", type=float, default=0.1, help="nominal steps (loop.method.min_strength_steps)")
    args = ap.parse_args()
    table = pd.DataFrame([row for path in args.records for row in rows_of(path)])
    table.to_csv(args.out, index=False)
    below = table[table.strength_fitted < args.floor]
    true = table[table.injected]
    print(f"floor {args.floor} nominal steps over {len(args.records)} records: injected effects named "
          f"{len(true)}, smallest fitted {true.strength_fitted.min():.3f} steps, taken out "
          f"{int(below.injected.sum())}; spurious named {int((~table.injected).sum())}, taken out "
          f"{int((~below.injected).sum())}")
    for path in args.records:
        before, after, n = exact_after(path, args.floor)
        print(f"  {path.name}: exact in-list {before} -> {after} of {n}")


if __name__ == "__main__":
    main()
