"""Results-page section "Transfer beyond the paper": the transfer table (docs/transfer.md) beside the paper's numbers
and the paper's reference model's decoded hard predictions, what each selection rule chose and on which data, and
the issue's aims checked against the method that cross-real selection picked (not the best test score)."""

from __future__ import annotations

import pandas as pd

from palpation.report import paper
from palpation.report.compare import TITLES, Section, aim_lines, aim_miss, truthy
from palpation.report.markdown import markdown, num

# config: (AP aim of the inductive method cross-real selection picks, the std aim over five seeds)
AIMS = {"A-to-B": (0.40, 0.02), "A-to-C": (0.30, 0.02)}


def aim_checks(df: pd.DataFrame) -> list[tuple[str, str, float, str, float, float]]:
    """(row label, column, value, sense, target, miss) of the AP and std aims, on the inductive cross_real choice."""
    out = []
    for config, (ap_aim, std_aim) in AIMS.items():
        pick = df[(df["config"] == config) & (df["selection"] == "cross_real") & df["chosen"].map(truthy)
                  & ~df["transductive"].map(truthy)]
        for _, r in pick.iterrows():
            label = f"{config} {r['method']} (cross_real, inductive)"
            out.append((label, "AP", float(r["ap_mean"]), ">=", ap_aim, aim_miss(float(r["ap_mean"]), ">=", ap_aim)))
            out.append((label, "AP std", float(r["ap_std"]), "<=", std_aim,
                        aim_miss(float(r["ap_std"]), "<=", std_aim)))
    return out


def decoded_reference(meat_meta: dict | None) -> str:
    """One sentence on the paper's reference model's hard predictions decoded from the Meat prediction video."""
    if not meat_meta or "ref_hard_positives" not in meat_meta:
        return ""
    n = int(meat_meta.get("nodes") or 0)
    share = f"{100 * meat_meta['ref_hard_positives'] / n:.1f} % of markers positive, " if n else ""
    return (f" The paper's own reference model, decoded from its Meat prediction video (`data/meat/meat.json`): "
            f"{share}accuracy {meat_meta['ref_hard_accuracy']:.3f} at its hard threshold; compare the "
            "`Positive at 0.5` column of A-to-C.")


def left_out_note(methods: list[str]) -> str:
    """The methods of conf/transfer/methods.yaml whose rows the table left out (transfer_table.py --leave-out)."""
    if not methods:
        return ""
    return (f"\nLeft out of this table, their runs not yet redone under the current selection rule: "
            f"{', '.join(f'`{m}`' for m in methods)} (`transfer_table.py --leave-out`).")


def transfer_section(df: pd.DataFrame, details: dict | None = None, meat_meta: dict | None = None) -> Section:
    """The table's rows per configuration, the choices with what chose them (`details`: transfer.json), the aims."""
    chosen_on = {(r["config"], r["method"], r["selection"]): r.get("chosen_on") or []
                 for r in (details or {}).get("rows", [])}
    picks = []
    for _, r in df[df["chosen"].map(truthy)].iterrows():
        ref = paper.SEED_SWEEP.get(r["config"], {})
        on = ", ".join(chosen_on.get((r["config"], r["method"], r["selection"]), [])) or "–"
        picks.append([f"{r['config']} ({paper.CONFIG_TITLES.get(r['config'], '')})", r["selection"],
                      "transductive" if truthy(r["transductive"]) else "inductive", r["method"], on,
                      f"{num(r['ap_mean'])} ± {num(r['ap_std'])}", num(r["auroc_mean"]),
                      f"{num(ref['ap'][0])} / {num(ref['auroc'][0])}" if ref else "–"])
    every = df.drop_duplicates(["config", "method"])
    rows = [[r["config"], r["method"], "yes" if truthy(r["transductive"]) else "", f"{num(r['ap_mean'])} ± "
             f"{num(r['ap_std'])}", num(r["auroc_mean"]), f"{100 * float(r['pos_share_05']):.1f} %",
             ", ".join(sorted(set(df[(df["config"] == r["config"]) & (df["method"] == r["method"])
                                     & df["chosen"].map(truthy)]["selection"])))]
            for _, r in every.iterrows()]
    bullets, gaps = aim_lines(aim_checks(df), str)
    body = ("Per configuration, every candidate method (`conf/transfer/methods.yaml`) trained with five seeds on the "
            "paper profile's data, and what each selection rule chose (docs/transfer.md): `sim_val` by the Sim "
            "validation AP, `cross_real` by the AP on the other labelled real set (a Silicone-scored model is chosen "
            "on Meat, and back); the scored set's labels choose nothing. Transductive methods read the scored set's "
            "own inputs (never its labels) and are chosen apart. The paper's column is its reference recipe "
            "(SPEC §15.3, mean over seeds)." + decoded_reference(meat_meta) + "\n\n"
            + markdown(["Config", "Selection", "Kind", "Chosen", "Chosen on", "AP (mean ± std)", "AUROC",
                        "Paper AP / AUROC"], picks)
            + left_out_note((details or {}).get("left_out", []))
            + "\n\nEvery method (the rows are the same for both rules; `transfer/transfer.csv`):\n\n"
            + markdown(["Config", "Method", "Transductive", "AP (mean ± std)", "AUROC", "Positive at 0.5",
                        "Chosen by"], rows))
    return Section("transfer", TITLES["transfer"], body, bullets, gaps, set(df["config"]))
