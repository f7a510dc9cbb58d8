"""Results-page sections for the real data and the twin: data sets, calibration, residual loop.

Same contract as `page_training`: the run's tables in, a Section out (ours | paper | difference, generated
bullets, the differences behind them). The paper's numbers come from `paper.py` (SPEC §13, §15.3, §15.8).
"""

from __future__ import annotations

import re

import pandas as pd

from palpation.camera import MM_PER_PX
from palpation.report.compare import TITLES, Gap, Section
from palpation.report.markdown import markdown, num, signed
from palpation.report.paper import CALIBRATION_MAE, DATASETS, TEST_SETS

TEST_SET = {"A-to-A": "sim", "A-to-B": "silicone", "A-to-C": "meat", "C-to-B": "silicone"}  # SPEC §1.1


def _rate(ours: float, paper: float | None) -> tuple[str, str, str]:
    """ours, paper, difference; the paper prints 4 d.p., so an equal rounding is no difference."""
    if paper is None:
        return num(ours), "–", "–"
    if round(ours, 4) == round(paper, 4):
        return num(ours), num(paper), "equal to 4 d.p."
    return num(ours), num(paper), f"{signed(ours - paper)}, {(ours - paper) / paper:+.1%}"


def data_sets(df: pd.DataFrame, sweep: pd.DataFrame | None = None, t4: pd.DataFrame | None = None,
              sim_twin: str | None = None) -> Section:
    """The data sets beside the paper's; `sim_twin` says which twin simulated the main Sim set, where recorded."""
    rows, gaps, bullets = [], [], []
    for _, r in df.iterrows():
        name, paper = r["dataset"], DATASETS.get(r["dataset"], {})
        rate = _rate(float(r["positive_rate"]), paper.get("positive_rate"))
        rows.append([name, int(r["trials"]), num(paper.get("trials"), 0), int(r["frames"]),
                     num(paper.get("frames"), 0), *rate])
        if "positive_rate" in paper:
            gaps.append(Gap(name, "positive_rate", float(r["positive_rate"]) - paper["positive_rate"], None))
            same = [k for k in ("trials", "frames") if k in paper and int(r[k]) == paper[k]]
            other = [f"{k} {int(r[k])} vs {paper[k]}" for k in ("trials", "frames") if k in paper and k not in same]
            bullets.append(f"{name}: {', '.join(same) or 'no counts'} as the reference"
                           + (f"; {', '.join(other)}" if other else "")
                           + f"; central-frame positive rate {rate[0]} vs {rate[1]} ({rate[2]}).")
    names = set(df["dataset"])
    if sweep is not None and "A-to-A" in set(sweep["config"]):  # Sim: the A-to-A test split's chance level
        chance = float(sweep.loc[sweep["config"] == "A-to-A", "chance"].mean())
        rate = _rate(chance, DATASETS["sim"]["positive_rate"])
        rows.append(["sim (A-to-A test split)", "–", num(DATASETS["sim"]["trials"], 0), "–", "–", *rate])
        gaps.append(Gap("sim", "positive_rate", chance - DATASETS["sim"]["positive_rate"], None))
        bullets.append(f"sim: A-to-A test-split positive rate {rate[0]} vs {rate[1]} ({rate[2]}).")
        names.add("sim")
    if sim_twin:
        bullets.append(f"sim: simulated by {sim_twin}.")
    body = ("Central-frame positive rate at L = 5, as the reference counts it (SPEC §7, §13.4–13.5); frames are "
            "clip-centre frames (viewer states).\n\n"
            + markdown(["set", "trials", "paper", "frames", "paper", "positive rate", "paper", "ours − paper"], rows))
    if t4 is not None:
        trows, match, differ = [], [], []
        for _, r in t4.iterrows():
            config = r["config"]
            nodes, pos = int(r["tp"] + r["fp"] + r["fn"] + r["tn"]), int(r["tp"] + r["fn"])
            p_nodes, p_pos = TEST_SETS.get(config, (None, None))
            trows.append([config, TEST_SET.get(config, "?"), f"{nodes:,}", num(p_nodes, 0), f"{pos:,}",
                          num(p_pos, 0), signed(pos - p_pos, 0) if p_pos else "–"])
            if p_nodes is not None:
                gaps += [Gap(config, "test_nodes", nodes - p_nodes, None), Gap(config, "test_positives",
                                                                                pos - p_pos, None)]
                (match if (nodes, pos) == (p_nodes, p_pos) else differ).append(
                    config if (nodes, pos) == (p_nodes, p_pos) else
                    f"{config} {nodes:,}/{pos:,} vs {p_nodes:,}/{p_pos:,}")
        body += ("\nTest sets as scored (central-frame nodes and positives, from Table 4's counts; paper SPEC "
                 "§15.3):\n\n" + markdown(["config", "test set", "nodes", "paper", "positives", "paper",
                                           "ours − paper"], trows))
        if match:
            bullets.append(f"Test sets identical to the paper's in nodes and positives: {', '.join(match)}.")
        if differ:
            bullets.append(f"Test sets that differ (nodes/positives): {'; '.join(differ)}.")
    return Section("data", TITLES["data"], body, bullets, gaps, names)


def calibration(df: pd.DataFrame) -> Section:
    has_paper_params = "paper_params_px" in df.columns
    rows, gaps = [], []
    for _, r in df.iterrows():
        i, p = r["interaction"], CALIBRATION_MAE.get(r["interaction"])
        fit = "" if "used_for_fit" not in df.columns else ("fit" if bool(r["used_for_fit"]) else "held out")
        ours = [i, fit, num(r["undeformed_px"], 2)] + ([num(r["paper_params_px"], 2)] if has_paper_params else [])
        ours += [f"{r['fitted_px']:.2f} ({r['fitted_mm']:.2f} mm)", signed(r["undeformed_px"] - r["fitted_px"], 2)]
        if p is None:
            rows.append(ours + ["–"] * 4)
            continue
        rows.append(ours + [num(p["undeformed"], 2), num(p["twin"], 2), signed(p["undeformed"] - p["twin"], 2),
                            signed(r["fitted_px"] - p["twin"], 2)])
        gaps += [Gap(i, "fitted_px", r["fitted_px"] - p["twin"], None),
                 Gap(i, "margin_px", (r["undeformed_px"] - r["fitted_px"]) - (p["undeformed"] - p["twin"]), None)]
    common = [i for i in df["interaction"] if i in CALIBRATION_MAE]
    bullets = []
    for label, subset in (("mean", common), ("mean without twist_z", [i for i in common if i != "twist_z"])):
        if not subset or (label != "mean" and len(subset) == len(common)):
            continue
        o = df.set_index("interaction").loc[subset]
        pu = sum(CALIBRATION_MAE[i]["undeformed"] for i in subset) / len(subset)
        pt = sum(CALIBRATION_MAE[i]["twin"] for i in subset) / len(subset)
        ou, of = o["undeformed_px"].mean(), o["fitted_px"].mean()
        rows.append([f"**{label}**", "", num(ou, 2)] + ([num(o["paper_params_px"].mean(), 2)] if has_paper_params
                                                        else [])
                    + [f"**{of:.2f} ({of * MM_PER_PX:.2f} mm)**", signed(ou - of, 2), num(pu, 2),
                       f"**{pt:.2f} ({pt * MM_PER_PX:.2f} mm)**", signed(pu - pt, 2), signed(of - pt, 2)])
        bullets.append(f"{label.capitalize()} over {len(subset)} photos: fitted twin {of:.2f} px ({of * MM_PER_PX:.2f} "
                       f"mm) vs the paper's twin {pt:.2f} px ({pt * MM_PER_PX:.2f} mm), {signed(of - pt, 2)} px; "
                       f"margin over the undeformed sensor {ou - of:.2f} px vs the paper's {pu - pt:.2f} px.")
    ours_worse = [r["interaction"] for _, r in df.iterrows() if r["fitted_px"] >= r["undeformed_px"]]
    paper_worse = [i for i in common if CALIBRATION_MAE[i]["twin"] >= CALIBRATION_MAE[i]["undeformed"]]
    bullets.append(f"Photos where the twin does not beat the undeformed sensor: ours {', '.join(ours_worse) or 'none'}"
                   f"; the paper's {', '.join(paper_worse) or 'none'}.")
    header = ["interaction", "role", "undeformed px"] + (["ours at paper's E, k_n"] if has_paper_params else []) + [
        "fitted px (mm)", "margin", "paper undeformed", "paper twin", "paper margin", "fitted − paper twin"]
    body = ("Marker MAE (px, 127 markers; 27.5 px/mm) of each interaction's photo against the simulated markers, "
            "beside an undeformed sensor (the rest template); margin = undeformed − twin (SPEC §15.8).\n\n"
            + markdown(header, rows))
    return Section("calibration", TITLES["calibration"], body, bullets, gaps, set(df["interaction"]))


def _interaction(photo: str) -> str | None:
    m = re.match(r"(press|twist_z|twist_x|slide)", photo)
    return m.group(1) if m else None


def loop(df: pd.DataFrame, per_state: pd.DataFrame | None = None) -> Section:
    rows = [[int(r["round"]), r["effect_added"] if r["effect_added"] != "none" else "calibrated twin",
             num(r["mae_fit_px"], 2), num(r["mae_heldout_px"], 2), num(r["mae_mean_mm"], 3),
             num(r["mae_mean_mm"] / MM_PER_PX, 2)] for _, r in df.iterrows()]
    first, last = df.iloc[0], df.iloc[-1]
    paper_px = sum(v["twin"] for v in CALIBRATION_MAE.values()) / len(CALIBRATION_MAE)
    paper_mm, final_mm = paper_px * MM_PER_PX, float(last["mae_mean_mm"])
    body = ("The rounds the loop kept: each adds the effect (or effect pair) that explains most of the remaining "
            "residual, kept only if the gate accepts it: the held-out change weighed against its own noise "
            "(rejected tries: `loop/tables/tries.csv`; verdict: `loop/report.md`). The paper has no loop; "
            "it stops at the calibrated twin, so the comparison is with that twin's MAE (SPEC §15.8).\n\n"
            + markdown(["round", "effect added", "MAE fit px", "MAE held-out px", "mean mm", "mean px"], rows)
            + f"\nFinal twin vs the paper's twin: {final_mm:.3f} mm ({final_mm / MM_PER_PX:.2f} px) vs "
              f"{paper_mm:.3f} mm ({paper_px:.2f} px), {signed(final_mm - paper_mm, 3)} mm.\n")
    bullets = [f"The paper has no residual loop. Our final twin's mean MAE is {final_mm:.3f} mm vs the paper's "
               f"calibrated twin {paper_mm:.3f} mm ({(final_mm - paper_mm) / paper_mm:+.0%}); the loop's own round 0 "
               f"(calibrated twin) is {first['mae_mean_mm']:.3f} mm.",
               f"Held-out photo: {first['mae_heldout_px']:.2f} → {last['mae_heldout_px']:.2f} px over "
               f"{len(df) - 1} kept round(s)."]
    gaps = [Gap(None, "mae_mean_mm", final_mm - paper_mm, None)]
    names = set()
    if per_state is not None and {"state", "final_px"} <= set(per_state.columns):  # loop/tables/per_state.csv
        prow = []
        for _, p in per_state.iterrows():
            i = _interaction(p["state"])
            twin = CALIBRATION_MAE.get(i, {}).get("twin")
            final = float(p["final_px"])
            fit = "yes" if str(p.get("fit")) == "True" else "held out"
            prow.append([p["state"], fit, num(p.get("baseline_px"), 2), num(p.get("round0_px"), 2),
                         num(final, 2), num(twin, 2), signed(final - twin, 2) if twin else "–"])
            if twin:
                gaps.append(Gap(i, "final_px", final - twin, None))
                names.add(i)
        body += ("\nPer photo (from `loop/tables/per_state.csv`), beside the paper's twin on the same interaction:\n\n"
                 + markdown(["photo", "fit", "undeformed px", "round 0 px", "final px", "paper twin px",
                             "final − paper twin"], prow))
    return Section("loop", TITLES["loop"], body, bullets, gaps, names)
