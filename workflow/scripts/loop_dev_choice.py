"""Choose between the default loop and one changed method on generative dev runs, by a rule fixed in advance.

    python workflow/scripts/loop_dev_choice.py DEFAULT_DIR CHANGED_DIR [--json OUT]

Each directory holds a generative self-test's selftest_general.json on the same dev seeds (the same truths).
The change is adopted only if it names the exact set in at least `--min-gain` more in-list runs and loses at
most one outside run on either outside measure (`unexplained`, nothing named beyond the truth). Prints
`default` or `changed` on the last line, so a device script can start the test split with the winner, and
the counts the rule read above it. Test seeds never enter: the test split is run once, after the choice.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def counts(directory: Path) -> dict:
    """In-list exact runs and the two outside measures as run counts (the summary holds shares)."""
    path = directory / "selftest_general.json"
    try:
        summary = json.loads(path.read_text())["summary"]["dev"]
    except (OSError, ValueError, KeyError) as exc:
        raise SystemExit(f"loop_dev_choice: {path}: no dev summary ({exc}); run the generative dev split first")
    n_in, n_out = summary["in_list_runs"], summary["out_of_list_runs"]
    return {"runs": summary["runs"], "seeds": summary["seeds"], "in_list": n_in, "outside": n_out,
            "exact": round(summary["exact_named"] * n_in),
            "outside_unexplained": round(summary["out_of_list_unexplained"] * n_out),
            "outside_clean": round(summary["out_of_list_no_extra"] * n_out)}


def choose(default: dict, changed: dict, min_gain: int = 1) -> str:
    if (default["seeds"], default["runs"]) != (changed["seeds"], changed["runs"]):
        raise SystemExit(f"loop_dev_choice: the two runs hold other draws (seeds {default['seeds']} x "
                         f"{default['runs']} against {changed['seeds']} x {changed['runs']}); compare like with like")
    better = changed["exact"] >= default["exact"] + min_gain
    kept = all(changed[k] >= default[k] - 1 for k in ("outside_unexplained", "outside_clean"))
    return "changed" if better and kept else "default"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("default", type=Path)
    ap.add_argument("changed", type=Path)
    ap.add_argument("--min-gain", type=int, default=1, help="more exact in-list runs the change must name")
    ap.add_argument("--json", type=Path, help="write the counts and the choice here too")
    args = ap.parse_args()
    a, b = counts(args.default), counts(args.changed)
    winner = choose(a, b, args.min_gain)
    for label, c in (("default", a), ("changed", b)):
        print(f"{label}: exact {c['exact']}/{c['in_list']}, outside unexplained {c['outside_unexplained']}/"
              f"{c['outside']}, outside clean {c['outside_clean']}/{c['outside']}")
    if args.json:
        args.json.write_text(json.dumps({"default": a, "changed": b, "choice": winner}, indent=1) + "\n")
    print(winner)


if __name__ == "__main__":
    main()
