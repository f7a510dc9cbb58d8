"""Loop outputs: the rounds table (CSV + Markdown), the final twin as a Hydra option, self-test tables.

`<out>/twin_fit/fitted.yaml` uses the calibration's mechanism (calibration.outputs): a config-group
option in package `twin`, loaded by any app composing `twin` with
    hydra.searchpath=[file://<out>] +twin_fit=fitted
It holds the fitted values and the switches the added effects need (phantom contact, shell thickness).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
import yaml

from palpation.calibration.objective import marker_mae_px
from palpation.camera import MM_PER_PX
from palpation.io import csv_text as io_csv_text
from palpation.io import save_text
from palpation.loop.effects import EFFECTS, PARAMS, bounds, twin_overrides
from palpation.loop.problem import Problem

REAL_COLUMNS = ("round", "effect_added", "residual_share_explained", "mae_fit_px", "mae_heldout_px",
                "mae_mean_mm")
TARGET_BELOW_BASELINE = 0.40  # and every photo >= 40 % below the undeformed sensor


def real_rows(p: Problem) -> list[dict]:
    """One row per kept round (round 0 = the calibrated twin), the columns of docs/results/loop_real.csv."""
    rows = []
    for r in p.rounds:
        if not r["accepted"]:
            continue
        a = r["after"]
        rows.append({"round": r["round"], "effect_added": r["effect"] or "none",
                     "residual_share_explained": r["share_explained"] if r["effect"] else float("nan"),
                     "mae_fit_px": a["fit"], "mae_heldout_px": a["heldout"],
                     "mae_mean_mm": a["all"] * MM_PER_PX})
    return rows


def csv_text(rows: list[dict], columns) -> str:
    return io_csv_text(rows, columns, digits=4, na_rep="")


def write_twin_fit(out_dir: Path, p: Problem, shell_thickness_m: float, record: Mapping,
                   integrator: Mapping | None = None) -> tuple[Path, Path]:
    """The final twin as a Hydra option (package twin) plus a readable record of every loop parameter.

    `integrator` (dt, substeps of the loop's twin) is written too: a stiff shell may need the smaller
    step the loop ran with, and the dataset must use the numerics the fit was made with."""
    used = ["E", *[n for e in p.effects for n in EFFECTS[e].params]]
    values = {n: p.params[n] for n in used}
    head = ("# @package twin\n# Final twin of palpation.apps.loop (effects: "
            f"{', '.join(p.effects) or 'none'}).\n"
            f"# Load with: hydra.searchpath=[file://{out_dir}] +twin_fit=fitted\n")
    option = Path(out_dir) / "twin_fit" / "fitted.yaml"
    overrides = twin_overrides(values, p.effects, shell_thickness_m)
    if integrator:
        overrides["integrator"] = {k: integrator[k] for k in ("dt", "substeps")}
    save_text(option, head + yaml.safe_dump(overrides, sort_keys=True))
    readable = {"effects": list(p.effects),
                "params": {n: {"value": float(p.params[n]), "unit": PARAMS[n].unit} for n in used},
                "twin": overrides, **record}
    params = Path(out_dir) / "fitted_params.yaml"
    save_text(params, yaml.safe_dump(readable, sort_keys=False))
    return option, params


def at_bounds(params: Mapping[str, float], names, overrides: Mapping | None = None,
              tol: float = 0.01) -> list[str]:
    """Searched names within `tol` of a bound (in log space where searched so): the fit wants more room."""
    out = []
    for n in names:
        low, high = bounds(n, overrides)
        f = np.log if PARAMS[n].log and low > 0 else (lambda x: x)
        u = (f(params[n]) - f(low)) / (f(high) - f(low))
        if u < tol or u > 1 - tol:
            out.append(n)
    return out


def _fmt_params(params: Mapping[str, float] | None, names) -> str:
    if not params:
        return ""
    return ", ".join(f"{n} = {params[n]:.4g}" for n in names)


def start_effects(p: Problem) -> list[str]:
    """Effects the starting twin already had (p.effects minus those the rounds added)."""
    added = [e for r in p.rounds if r["accepted"] for e in r.get("effects", [])]
    return [e for e in p.effects if e not in added]


def verdict_lines(p: Problem, meta: Mapping) -> list[str]:
    """The report's first lines (issue 13.6): what was found and how surely, bounds, what remains, target."""
    kept = [r for r in p.rounds if r["round"] > 0 and r["accepted"] and set(r.get("effects", [])) <= set(p.effects)]
    found = "; ".join(f"**{r['effect']}** (round {r['round']}: {r['after']['gate']['why']})" for r in kept)
    start = start_effects(p)
    L = ["## Verdict", "",
         f"* Effects found: {found or '**none**'}" + (f"; the starting twin already had {', '.join(start)}"
                                                     if start else "") + "."]
    small = (p.parsimony or {}).get("negligible", [])
    dropped = [e for e in (p.parsimony or {}).get("dropped", []) if e not in small]
    if small:  # loop.parsimony: kept by a round, ended within loop.method.min_strength_steps of off
        L.append(f"* Taken out after the final refit, negligible (closer to off than loop.method.min_strength_steps "
                 f"nominal steps): {', '.join(small)}; not in the fitted twin.")
    if dropped:  # loop.parsimony: kept by a round, not needed by the final twin
        L.append(f"* Taken out after the final refit, not significantly needed by the final twin (loop.parsimony): "
                 f"{', '.join(dropped)}; not in the fitted twin.")
    edge = at_bounds(p.params, p.searched, meta.get("bounds"))
    if edge:
        L.append("* At a search bound: " + ", ".join(f"{n} = {p.params[n]:.4g}" for n in edge)
                 + (" — E at a bound is a symptom: the stiffness absorbs what a missing effect would explain"
                    if "E" in edge else "") + ".")
    else:
        L.append("* No fitted parameter at a search bound.")
    f = p.final or {}
    unc = f.get("uncertainty", {})
    if unc.get("dofs"):
        sd = ", ".join(d["sd"] for d in unc["dofs"])
        trade = [f"{k} (ρ = {v:+.2f})" for k, v in unc["corr"].items() if abs(v) > 0.9]
        L.append(f"* Uncertainty (Laplace, 1 sd): {sd}" + (f"; trading pairs, poorly determined jointly: "
                                                            f"{', '.join(trade)}" if trade else "") + ".")
    ref, first = p.reference_attribution, next((r for r in p.rounds if r["round"] == 1), None)
    if ref is not None and first is not None:
        same = set(ref["best_subset"]) == set(first["best_subset"])
        L.append(f"* Compensation guard: the attribution on the starting twin's residual (before E was fitted) "
                 f"keeps {'+'.join(ref['best_subset']) or 'nothing'} ({ref['best_subset_share']:.0%}), on the round-0 "
                 f"twin {'+'.join(first['best_subset']) or 'nothing'} ({first['best_subset_share']:.0%})"
                 + ("." if same else ": they differ, so the round-0 stiffness absorbed part of a signature."))
    ties = [f"{r['effect']} ~ {' ~ '.join(r['indistinguishable'])} (round {r['round']})" for r in kept
            if r.get("indistinguishable")]
    if ties:
        L.append("* Indistinguishable on these states (neither passes the gate against the other; the smaller set "
                 "is kept, loop.compete): " + "; ".join(ties) + ".")
    nulled = [r for r in p.rounds if "not beyond re-fitting" in ((r.get("after") or {}).get("gate") or {}).get("why", "")]
    if nulled:
        L.append("* Refused because re-fitting the current parameters alone (the null try) did as well: "
                 + ", ".join(f"{r['effect']} (round {r['round']})" for r in nulled) + ".")
    rf = f.get("refit")
    if rf and rf["kept"]:
        L.append(f"* Final refit ({rf['kept']} Levenberg-Marquardt step(s) of the fitted parameters, best of "
                 f"{rf.get('starts', 1)} start(s)): fitted MAE "
                 f"{rf['before']['fit']:.2f} → {rf['after']['fit']:.2f} px, held-out {rf['before']['heldout']:.2f} → "
                 f"{rf['after']['heldout']:.2f} px"
                 + ("." if rf.get("converged", True) else "; stopped at loop.method.final_refit_iters while still descending, "
                    "so the residual below is partly what the search left."))
    t = f.get("test")
    if t:
        twin = t.get("beyond", "candidates") == "twin"
        head = (f"* Remaining residual: RMS {t['rms_px']:.2f} px per coordinate on the fitted states against detector "
                f"noise {t['noise_px']:.2f} px ({f.get('noise_source', '')}); "
                + (f"beyond the final twin's own parameters {t['excess_ratio']:.1f}× the noise (χ² p = "
                   f"{t['p_value']:.2g}); the remaining candidates' columns would span "
                   f"{t['explained_by_candidates']:.0%} of it (their tries are in the rounds above)." if twin else
                   f"the candidates could still explain {t['explained_by_candidates']:.0%} of it; the rest is "
                   f"{t['excess_ratio']:.1f}× the noise (χ² p = {t['p_value']:.2g})."))
        L.append(head)
        if t["unexplained"]:
            d = f.get("discrepancy", {})
            L.append(f"* **Unexplained residual remains**: {f['structure']['text']}. The final twin is not claimed "
                     f"to explain it. Last resort, not physics: a rank-1 marker-field discrepancy would take the "
                     f"fitted MAE to {d.get('mae_fit_px', float('nan')):.2f} px and the held-out to "
                     f"{d.get('mae_heldout_px', float('nan')):.2f} px.")
        else:
            L.append("* No unexplained residual: what remains is at the noise." if twin else
                     "* No unexplained residual: what remains is noise or within what the candidates span.")
    mean = meta.get("mean_px")
    if meta.get("target_applies"):
        ok = mean <= meta["target_mm"] / MM_PER_PX
        L.append(f"* Target (set for this photo set): mean {mean * MM_PER_PX:.3f} mm against "
                 f"{meta['target_mm']} mm: {'met' if ok else 'missed'}.")
    else:
        L.append(f"* No accuracy target applies to this set (the {meta.get('target_mm')} mm target was set for "
                 f"`{meta.get('target_set')}` only); mean {mean * MM_PER_PX:.3f} mm.")
    return L + [""]


def real_markdown(p: Problem, decs: Mapping[str, list], baseline: Mapping[str, float], meta: Mapping) -> str:
    """results/loop/report.md: verdict, rounds, per-photo MAE against the targets, attribution, residual modes."""
    L = [f"# Residual loop on `{meta['source']}`", "", *verdict_lines(p, meta),
         f"Fitted: {', '.join(t.name for t in p.targets if t.fit)}; held out: "
         f"{', '.join(t.name for t in p.targets if not t.fit) or 'none'}. Mesh {meta['mesh']}, "
         f"{meta['n_trials']} Optuna trials per recalibration, candidates {', '.join(meta['candidates'])}.", "",
         "## Rounds", "",
         "| round | effect | share explained (linear) | realised share | MAE fit px | MAE held-out px "
         "| mean mm | kept | parameters after |", "|---" * 9 + "|"]
    present = start_effects(p)  # effects in the twin before each round
    for r in p.rounds:
        a, b = r["after"], r["before"]
        names = ["E", *[n for e in present for n in EFFECTS[e].params]]
        new = r.get("effects") or ([r["effect"]] if r["effect"] else [])
        if r["accepted"]:
            present += new
        if r["round"] == 0:
            L.append(f"| 0 | calibrated twin | | | {a['fit']:.2f} | {a['heldout']:.2f} | "
                     f"{a['all'] * MM_PER_PX:.3f} | yes | {_fmt_params(r['params_after'], names)} |")
            continue
        if a is None:
            L.append(f"| {r['round']} | none named (BIC) | | | {b['fit']:.2f} | {b['heldout']:.2f} | | "
                     "stop | |")
            continue
        realised = 1 - a["fit_energy"] / b["fit_energy"] if "fit_energy" in a else float("nan")
        L.append(f"| {r['round']} | {r['effect']} | {r['share_explained']:.1%} | {realised:.1%} | "
                 f"{b['fit']:.2f} → {a['fit']:.2f} | {b['heldout']:.2f} → {a['heldout']:.2f} | "
                 f"{a['all'] * MM_PER_PX:.3f} | {'yes' if r['accepted'] else 'no'}: {a.get('gate', {}).get('why', '')} | "
                 f"{_fmt_params(r['params_after'], [*names, *(n for e in new for n in EFFECTS[e].params)])} |")
    L += ["", "## Per photo against the targets", "",
          "| photo | fit | undeformed sensor px | round 0 px | final px | final mm | below baseline | target |",
          "|---" * 8 + "|"]
    first, final = p.rounds[0], meta["final_markers"]
    finals = []
    for i, t in enumerate(p.targets):
        m0, m1 = marker_mae_px(first["markers_after"][i], t.markers), marker_mae_px(final[i], t.markers)
        finals.append(m1)
        below = 1 - m1 / baseline[t.name]
        verdict = ("met" if below >= TARGET_BELOW_BASELINE else "missed") if meta.get("target_applies") else "n/a"
        L.append(f"| {t.name} | {'yes' if t.fit else 'held out'} | {baseline[t.name]:.2f} | {m0:.2f} | "
                 f"{m1:.2f} | {m1 * MM_PER_PX:.3f} | {below:.0%} | {verdict} |")
    mean = float(np.mean(finals))
    if meta.get("target_applies"):
        goal = meta["target_mm"] / MM_PER_PX
        verdict = "met" if mean <= goal else f"missed by {mean - goal:.2f} px"
        L += ["", f"Mean over the photos: {mean:.2f} px ({mean * MM_PER_PX:.3f} mm) against the target "
              f"{goal:.2f} px ({meta['target_mm']} mm): {verdict}. Undeformed-sensor baseline (rest template vs "
              f"photo) mean {np.mean(list(baseline.values())):.2f} px; every photo must end >= "
              f"{TARGET_BELOW_BASELINE:.0%} below its own baseline.", ""]
    else:
        L += ["", f"Mean over the states: {mean:.2f} px ({mean * MM_PER_PX:.3f} mm); no target applies to this "
              "set.", ""]
    edge = at_bounds(p.params, p.searched, meta.get("bounds"))
    if edge:
        L += [f"At a search bound in the final twin: {', '.join(f'{n} = {p.params[n]:.4g}' for n in edge)} "
              "(the fitted photos want more room than the stable range allows; see docs/loop.md).", ""]
    L += ["## Attribution per round (share of the fitted residual each effect explains; with "
          "loop.method.attribute_given_refit, of what re-fitting the twin's own parameters leaves)", ""]
    for i, r in enumerate(p.rounds[1:], 1):
        if p.rounds[i - 1]["round"] == r["round"]:
            continue  # a second try of the same round shares its attribution
        ranks = ", ".join(f"{x['effect']} {x['share']:.1%} (ΔBIC {x['bic_delta']:.0f})" for x in r["ranking"])
        L.append(f"* round {r['round']}: {ranks}; BIC-best subset {r['best_subset'] or 'empty'} "
                 f"({r['best_subset_share']:.1%}).")
    L += ["", "## Residual modes (share of the residual energy; stretch axis vs slide direction)", "",
          "| photo | twin | MAE px | translation | rotation | radial | stretch/shear | local | t (px) "
          "| rot (deg) | scale % | stretch % @ axis | axis vs slide | local central |", "|---" * 14 + "|"]
    for name, rows in decs.items():
        for label, d in rows:
            s = d.shares
            vs = "" if d.axis_vs_slide_deg is None else f"{d.axis_vs_slide_deg:.0f}°"
            L.append(f"| {name} | {label} | {d.mae_px:.2f} | {s['translation']:.0%} | {s['rotation']:.0%} | "
                     f"{s['radial']:.0%} | {s['stretch_shear']:.0%} | {s['local']:.0%} | "
                     f"({d.translation_px[0]:.1f}, {d.translation_px[1]:.1f}) | {d.rotation_deg:.2f} | "
                     f"{d.scale_pct:.2f} | {d.stretch_pct:.2f} @ {d.stretch_axis_deg:.0f}° | {vs} | "
                     f"{d.local_central_fraction:.0%} |")
    L += ["", "Figures: `residuals/residual_<photo>.png` (quivers, round 0 vs final), `modes.png`, "
          "`rounds.png`. The final twin: `twin_fit/fitted.yaml` (see docs/loop.md).", ""]
    return "\n".join(L)


def selftest_markdown(rows: list[dict], table: Mapping[str, Mapping[str, int]], summ: Mapping,
                      meta: Mapping) -> str:
    cols = list(next(iter(table.values())).keys())
    pct = lambda x: "n/a" if x != x else f"{x:.0%}"  # noqa: E731  (NaN: no run of that kind)
    L = ["# Residual loop self-test", "",
         f"{summ['runs']} runs ({meta['runs_per_case']} per case, up to {meta['max_rounds']} rounds): hidden effects "
         f"at random strengths in [{meta['low']}, {meta['high']}] nominal steps, Gaussian marker noise "
         f"{meta['noise_px']} px per coordinate; states {meta['states']} (held out {meta['holdout']}); starting twin "
         f"with {meta['base_effects'] or 'no effect'} on. Unexplained: chi-square p < {meta['alpha']} and RMS "
         f"outside the candidates' span > {meta['ratio']} x noise.", "",
         f"* exact in-list set named (and not `unexplained`): **{pct(summ['exact_named'])}** of "
         f"{summ['in_list_runs']} in-list runs (aim >= 85 %)",
         f"* MAE cut on in-list runs: **{pct(summ['mae_cut_mean'])}** (aim >= 70 %); mean MAE over all runs "
         f"{summ['mae_before_mean_px']:.2f} → {summ['mae_after_mean_px']:.2f} px",
         f"* out-of-list runs reported `unexplained`: **{pct(summ['out_of_list_unexplained'])}** of "
         f"{summ['out_of_list_runs']} (aim >= 80 %)",
         f"* in-list runs reported `unexplained`: **{summ['in_list_unexplained']}** (aim 0)",
         f"* gate over {summ['gate_tries']} tries: false accept {pct(summ['gate_false_accept'])} (an effect set not "
         f"all injected passed), false reject {pct(summ['gate_false_reject'])} (an injected subset refused); refused "
         f"because re-fitting alone did as well (null try): {summ.get('null_refused_wrong', 0)} wrong, "
         f"{summ.get('null_refused_right', 0)} injected; passed the gate but lost the round's competition "
         f"(loop.compete): {summ.get('replaced', 0)}", "",
         "## Confusion (rows named, columns injected; a run counts in every pair of its sets)", "",
         "| named \\ injected | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for n, counts in table.items():
        L.append(f"| {n} | " + " | ".join(str(counts[c]) for c in cols) + " |")
    L += ["", "## Runs", "", "| run | injected | strength | named | MAE before | MAE after | residual / noise |",
          "|---" * 7 + "|"]
    for r in rows:
        L.append(f"| {r['run']} | {r['effects_injected']} | {r['strength']:.2f} | {r['effects_named']} | "
                 f"{r['mae_before_px']:.2f} | {r['mae_after_px']:.2f} | {r['excess_ratio']:.1f} |")
    return "\n".join(L) + "\n"


def real_tables(p: Problem, decs: Mapping[str, list], baseline: Mapping[str, float]) -> dict[str, tuple]:
    """The report's tables as rows for CSV files beside report.md (name -> (rows, columns))."""
    tries = []
    for r in p.rounds:
        a, b = r["after"], r["before"]
        gate = (a or {}).get("gate", {})
        tries.append({"round": r["round"], "effects": r["effect"] or ("calibrated twin" if r["round"] == 0 else "none"),
                      "accepted": r["accepted"], "share_linear": r["share_explained"],
                      "mae_fit_before_px": b["fit"] if b else float("nan"), "mae_fit_after_px": a["fit"] if a else float("nan"),
                      "mae_heldout_before_px": b["heldout"] if b else float("nan"),
                      "mae_heldout_after_px": a["heldout"] if a else float("nan"),
                      "heldout_gain_px": gate.get("gain_px", float("nan")), "heldout_z": gate.get("z", float("nan")),
                      "gate": gate.get("why", ""), "best_subset": "+".join(r["best_subset"])})
    attribution = [{"round": r["round"], "effect": x["effect"], "share": x["share"], "bic_delta": x["bic_delta"]}
                   for i, r in enumerate(p.rounds) if r["round"] > 0 and (i == 0 or p.rounds[i - 1]["round"] != r["round"])
                   for x in r["ranking"]]
    first = p.rounds[0]["markers_after"]
    photos = [{"state": t.name, "fit": t.fit, "baseline_px": baseline[t.name],
               "round0_px": marker_mae_px(first[i], t.markers), "final_px": marker_mae_px(p.markers[i], t.markers),
               "final_mm": marker_mae_px(p.markers[i], t.markers) * MM_PER_PX} for i, t in enumerate(p.targets)]
    modes = [{"state": n, "twin": lab, **d.row()} for n, rows in decs.items() for lab, d in rows]
    f = p.final or {}
    unc = [{"dof": d["dof"], "sd_nominal_steps": d["sd_steps"], "sd": d["sd"]} for d in f.get("uncertainty", {}).get("dofs", [])]
    unc += [{"dof": k, "sd_nominal_steps": float("nan"), "sd": f"corr {v:+.3f}"} for k, v in
            f.get("uncertainty", {}).get("corr", {}).items()]
    test = {k: v for k, v in f.get("test", {}).items()}
    final = [{**test, "structure": f.get("structure", {}).get("text", ""), "noise_source": f.get("noise_source", ""),
              **{f"discrepancy_{k}": v for k, v in f.get("discrepancy", {}).items()}}] if test else []
    return {"tries": (tries, tuple(tries[0])), "attribution": (attribution, ("round", "effect", "share", "bic_delta")),
            "per_state": (photos, tuple(photos[0])), "modes": (modes, tuple(modes[0]) if modes else ()),
            "uncertainty": (unc, ("dof", "sd_nominal_steps", "sd")),
            "final_check": (final, tuple(final[0]) if final else ())}
