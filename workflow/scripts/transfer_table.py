"""Write the transfer table from per-seed run records (docs/transfer.md):

    python workflow/scripts/transfer_table.py --runs-root results/transfer --out docs/results/transfer.csv \
        --configs A-to-B A-to-C C-to-B --seeds 0 1 2 3 4

Reads <runs-root>/<method>/<config>/L<clip-len>/seed<s>/{metrics.json,scores.npz} for every method of --methods;
a missing run is an error (no row is written from fewer seeds). Writes the CSV and a JSON beside it. --leave-out
METHOD... writes the table without those methods' rows (runs made under an earlier rule and not yet redone): the
JSON records them as left out.
"""

from __future__ import annotations

import argparse
import sys

from palpation.readers import one_line
from palpation.transfer.report import read_methods, table, write_table


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs-root", required=True)
    p.add_argument("--methods", default="conf/transfer/methods.yaml")
    p.add_argument("--configs", nargs="+", default=["A-to-B", "A-to-C", "C-to-B"])
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    p.add_argument("--clip-len", type=int, default=5)
    p.add_argument("--crossfit", nargs="*", default=[], metavar="CONFIG=FOLDS",
                   help="configurations whose cross_real choice is cross-fitted on their own trials")
    p.add_argument("--leave-out", nargs="*", default=[], metavar="METHOD",
                   help="methods of --methods whose rows the table leaves out (recorded in the JSON)")
    p.add_argument("--out", default="docs/results/transfer.csv")
    a = p.parse_args(argv)
    try:
        crossfit = {c: int(n) for c, _, n in (x.partition("=") for x in a.crossfit)}
        if len(set(a.seeds)) != len(a.seeds) or a.clip_len < 1:
            raise ValueError(f"--seeds {a.seeds} must be distinct and --clip-len {a.clip_len} >= 1")
        methods = read_methods(a.methods)
        unknown = sorted(set(a.leave_out) - set(methods))
        if unknown:
            raise ValueError(f"--leave-out {unknown}: not methods of {a.methods} (it has {sorted(methods)})")
        kept = {name: spec for name, spec in methods.items() if name not in a.leave_out}
        rows = table(a.runs_root, kept, a.configs, a.seeds, a.clip_len, crossfit)
        write_table(rows, a.out, left_out=sorted(a.leave_out))
    except (ValueError, OSError) as exc:
        print(f"transfer_table: {one_line(exc)}", file=sys.stderr)
        return 1
    print(f"{len(rows)} rows -> {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
