"""The docs' numbers of the transfer table (docs/results/transfer.csv), for report.docnumbers."""

from __future__ import annotations

from pathlib import Path

from palpation.report.compare import truthy
from palpation.report.records import record_csv as _csv


def transfer_choice(results: Path, config: str, transductive: bool = False) -> str:
    """The method the cross_real rule chose for `config` (docs/results/transfer.csv), its AP, and the reference's."""
    table = _csv(results, "transfer.csv", ("config", "method", "selection", "transductive", "chosen", "ap_mean",
                                           "ap_std"))
    rows = table.query("config == @config and selection == 'cross_real'")
    pick = rows[rows["chosen"].map(truthy) & (rows["transductive"].map(truthy) == transductive)]
    ref = rows[rows["method"] == "reference"]
    if len(pick) != 1 or len(ref) != 1:
        raise ValueError(f"record {results / 'transfer.csv'}: no single cross_real choice and reference row of "
                         f"{config}; regenerate it (workflow/scripts/transfer_table.py)")
    p = pick.iloc[0]
    if p["method"] == "reference":  # the paper's recipe itself: no alternative ranked above it
        return f"`reference` (the paper's recipe) AP {p['ap_mean']:.4f} ± {p['ap_std']:.4f}"
    return f"`{p['method']}` AP {p['ap_mean']:.4f} ± {p['ap_std']:.4f} (reference recipe {ref.iloc[0]['ap_mean']:.4f})"


TRANSFER_KEYS = {  # the cross_real rule's choice per Sim-trained configuration, inductive and transductive
    "transfer.silicone": lambda r: transfer_choice(r, "A-to-B"),
    "transfer.meat": lambda r: transfer_choice(r, "A-to-C"),
    "transfer.silicone_transductive": lambda r: transfer_choice(r, "A-to-B", transductive=True),
    "transfer.meat_transductive": lambda r: transfer_choice(r, "A-to-C", transductive=True),
}
