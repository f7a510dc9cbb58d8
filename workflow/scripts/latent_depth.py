"""Estimate each real slide's press depth from its unlabelled marker motion with a twin-made lookup
(docs/transfer.md):

    python -m palpation.apps.simulate set=depth_bank 'bank_depths_mm=[1,2,3,4,5,6]' twin.contact.phantom_contact=true \
        twin.contact.k_s=<the loop's k_s> out.dir=results/transfer/bank
    python workflow/scripts/latent_depth.py --bank results/transfer/bank/manifest.json \
        --out results/transfer/latent_depth.csv

Writes the estimates CSV (set, trial, depth_mm, raw_mm unclipped, in_bank: false where the lookup extrapolates,
signature), `<stem>_bank.csv` (the bank's depths and fitted
depths) and `<stem>.json` (the lookup's coefficients and leave-one-out error). Labels are not read.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from palpation.io import csv_text, save_json, save_text
from palpation.readers import one_line


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bank", required=True, help="manifest.json of a set=depth_bank Sim set")
    p.add_argument("--silicone", default="results/data/silicone/silicone.npz")
    p.add_argument("--meat", default="results/data/meat/meat.npz")
    p.add_argument("--rest", default="template", choices=["template", "ideal"], help="the real slides' rest layout")
    p.add_argument("--out", default="results/transfer/latent_depth.csv")
    a = p.parse_args(argv)
    try:
        from palpation.graph.layout import rest_layout
        from palpation.transfer.latent import SIGNATURE, bank_lookup, real_estimates

        lookup, bank = bank_lookup(a.bank)
        rows = real_estimates(lookup, {"silicone": a.silicone, "meat": a.meat}, rest_layout(a.rest))
        out = Path(a.out)
        save_text(out, csv_text(rows, ("set", "trial", "depth_mm", "raw_mm", "in_bank", *SIGNATURE), 4))
        save_text(out.with_name(out.stem + "_bank.csv"),
                  csv_text(bank, ("trial", "depth_mm", "fitted_mm", *SIGNATURE), 4))
        save_json(out.with_suffix(".json"), {"coef": lookup.coef.tolist(), "signature": list(SIGNATURE),
                                             "loo_rmse_mm": lookup.loo_rmse_mm, "n_bank": lookup.n_bank,
                                             "bank_mm": list(lookup.bank_mm),
                                             "bank": str(a.bank)})
    except (ValueError, OSError) as exc:
        print(f"latent_depth: {one_line(exc)}", file=sys.stderr)
        return 1
    outside = [f"{r['set']} {r['trial']}" for r in rows if r["in_bank"] == "false"]
    print(f"{len(rows)} slides -> {a.out} (bank leave-one-out error {lookup.loo_rmse_mm:.3f} mm; "
          f"{len(outside)} outside the bank's depths{': ' + ', '.join(outside) if outside else ''})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
