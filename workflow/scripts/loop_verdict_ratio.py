"""The final check's ratio (loop.method.verdict_ratio) chosen on generative dev records, without re-running the loop.

    python workflow/scripts/loop_verdict_ratio.py OUT_CSV RECORD.csv [RECORD.csv ...]

The verdict calls a residual unexplained when its RMS beyond the final twin's own parameters exceeds the ratio x the
noise (and is significant at alpha, which at these sizes every excess above about 1.15 is). The ratio feeds nothing
back once the search's own above-the-noise decisions keep theirs (loop.method.unexplained_ratio), so a record's final
twins stand and its `excess_ratio` column rescored at another ratio is the verdict the loop would have given.

The rule (dev records only choose it): the runs whose exact in-list set was named are the verdict's null (their twin is
the truth's, what remains is noise); the ratio is the smallest of GRID at or above MARGIN x the largest excess of
such a run over every record given. Printed per ratio: exact runs flagged (the harm), outside runs flagged, inexact
in-list runs flagged. A record whose `unexplained` column does not match excess > its own ratio (RECORDED_RATIO) is
refused: then the excess is not the verdict's. OUT_CSV: ratio, records, exact_runs, exact_flagged, outside_runs,
outside_flagged, inexact_runs, inexact_flagged, chosen.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

from palpation.report.loop_numbers import general_exact, selftest_runs

GRID = (1.25, 1.5, 1.75, 2.0)
MARGIN = 1.15  # above the null's largest value: a few dev records do not show the tail
RECORDED_RATIO = 2.0  # the ratio every dev record was made with


def runs_of(paths: list[Path]) -> list[dict]:
    out = []
    for path in paths:
        for r in selftest_runs(path.parent, path.name):
            if bool(r["unexplained"]) != (r["excess_ratio"] > RECORDED_RATIO):
                raise ValueError(f"{path}: run {r['run']} has unexplained={r['unexplained']} at excess "
                                 f"{r['excess_ratio']:.3f}: not a record of ratio {RECORDED_RATIO}")
            out.append({**r, "record": path.name})
    return out


def table(runs: list[dict]) -> pd.DataFrame:
    in_list = [r for r in runs if not r["unlisted"]]  # general_exact's flags follow these runs' order
    flags = general_exact(runs)
    exact = [r for r, f in zip(in_list, flags) if f]
    inexact = [r for r, f in zip(in_list, flags) if not f]
    outside = [r for r in runs if r["unlisted"]]
    floor = MARGIN * max(r["excess_ratio"] for r in exact)
    chosen = min((g for g in GRID if g >= floor), default=max(GRID))
    rows = [{"ratio": g, "records": len({r["record"] for r in runs}),
             "exact_runs": len(exact), "exact_flagged": sum(r["excess_ratio"] > g for r in exact),
             "outside_runs": len(outside), "outside_flagged": sum(r["excess_ratio"] > g for r in outside),
             "inexact_runs": len(inexact), "inexact_flagged": sum(r["excess_ratio"] > g for r in inexact),
             "chosen": g == chosen} for g in GRID]
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("records", nargs="+", type=Path)
    a = ap.parse_args(argv)
    try:
        t = table(runs_of(a.records))
    except (ValueError, OSError) as exc:
        print(f"loop_verdict_ratio: {exc}", file=sys.stderr)
        return 1
    a.out.parent.mkdir(parents=True, exist_ok=True)
    t.to_csv(a.out, index=False)
    print(t.to_string(index=False))
    print(f"chosen: {t.loc[t['chosen'], 'ratio'].item()} -> {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
