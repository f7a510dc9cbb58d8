"""The generative self-test's scores (the issue's measures) and its markdown page, per split."""

from __future__ import annotations

import dataclasses
from collections import Counter
from pathlib import Path
from typing import Mapping

import numpy as np

from palpation.io import save_json, save_text
from palpation.loop.generative_config import SPLITS
from palpation.loop.selftest.generative import COLUMNS, rows_csv
from palpation.loop.unlisted import UNLISTED_PREFIX

NAN = float("nan")


def _share(flags) -> float:
    flags = list(flags)
    return float(np.mean(flags)) if flags else NAN


def exact(r: Mapping) -> bool:
    """The loop named the injected in-list set, no more and no less (`unexplained` aside)."""
    return set(r["named"]) == set(r["injected_effects"])


def power_floor_px(noise_px: float, gate_fit_rel: float) -> float:
    """The MAE before below which the gate's fit arm cannot accept (docs/loop.md, run 10): the fitted MAE cannot
    fall below the noise's own, noise x sqrt(pi / 2), and must fall by gate_fit_rel."""
    return noise_px * np.sqrt(np.pi / 2) / (1.0 - gate_fit_rel) if gate_fit_rel < 1 else np.inf


def split_summary(rows: list[dict], floor_px: float) -> dict:
    inl = [r for r in rows if not r["unlisted"]]
    out = [r for r in rows if r["unlisted"]]
    cut = [1.0 - r["mae_after_px"] / r["mae_before_px"] for r in inl
           if r["mae_before_px"] and r["mae_after_px"] is not None and r["mae_before_px"] > 0]
    kinds = sorted({u for r in out for u in r["unlisted"]})
    return {
        "runs": len(rows), "in_list_runs": len(inl), "out_of_list_runs": len(out),
        # in-list runs (no outside effect), 0 effects included (then: nothing named)
        "exact_named": _share(exact(r) for r in inl),
        "exact_named_3": _share(exact(r) for r in inl if r["n_effects"] == 3),
        "exact_named_by_n": {n: _share(exact(r) for r in inl if r["n_effects"] == n)
                             for n in sorted({r["n_effects"] for r in inl})},
        "exact_and_clean": _share(exact(r) and not r["unexplained"] for r in inl),
        # against the oracle's identifiable truth (loop.selftest.oracle), on the in-list runs that have it
        "oracle_runs": sum("identifiable" in r for r in inl),
        "exact_identifiable": _share(set(r["named"]) == set(r["identifiable"]) for r in inl if "identifiable" in r),
        "not_identifiable": dict(Counter(e for r in inl if "identifiable" in r for e in r["injected_effects"]
                                         if e not in r["identifiable"])),
        "mae_cut_mean": float(np.mean(cut)) if cut else NAN,
        "unexplained_on_exact": int(sum(exact(r) and r["unexplained"] for r in inl)),
        "in_list_unexplained": int(sum(r["unexplained"] for r in inl)),
        # in-list runs whose injected effects stayed under the gate's power (no fault of the search)
        "below_power": int(sum(r["n_effects"] > 0 and (r["mae_before_px"] or 0.0) < floor_px for r in inl)),
        # out-of-list runs
        "out_of_list_unexplained": _share(r["unexplained"] for r in out),
        "out_of_list_no_extra": _share(set(r["named"]) <= set(r["injected_effects"]) for r in out),
        "out_of_list_unexplained_by_kind": {k: _share(r["unexplained"] for r in out if k in r["unlisted"])
                                            for k in kinds},
        "by_effect": by_effect(inl),
        "redrawn": int(sum(r["redrawn"] > 0 for r in rows)),
        "seeds": sorted({r["seed"] for r in rows}),
    }


def by_effect(inl: list[dict]) -> dict[str, dict[str, int]]:
    """Per in-list effect over in-list runs: how often it was injected, named where injected, and named where not
    (spurious). Where the misses and spurious names lie, which the set-level share hides."""
    effects = sorted({e for r in inl for e in [*r["injected_effects"], *r["named"]]})
    return {e: {"injected": sum(e in r["injected_effects"] for r in inl),
                "found": sum(e in r["injected_effects"] and e in r["named"] for r in inl),
                "spurious": sum(e in r["named"] and e not in r["injected_effects"] for r in inl)} for e in effects}



def summary(rows: list[dict], noise_px: float, gate_fit_rel: float) -> dict:
    """Per split present: the issue's measures (split_summary)."""
    floor = power_floor_px(noise_px, gate_fit_rel)
    return {"power_floor_px": floor, **{s: split_summary([r for r in rows if r["split"] == s], floor)
                                        for s in SPLITS if any(r["split"] == s for r in rows)}}


def _pct(x: float) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{100 * x:.0f}%"


def _num(x) -> str:
    return "n/a" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.2f}"


def markdown(rows: list[dict], summ: Mapping, meta: Mapping) -> str:
    lines = ["# Residual loop: generative self-test", "",
             f"Each run draws its truth (loop.generative, fingerprint {meta['fingerprint']}): 0-3 in-list effects "
             f"(P = {meta['n_effects']}), log-uniform strengths, E in {meta['E']} Pa, k_s in {meta['k_s']} N/m where "
             f"contact is on, and in {_pct(meta['unlisted_share'])} of runs one outside effect "
             f"({', '.join(meta['unlisted'])}); noise {meta['noise_px']} px per coordinate; up to {meta['max_rounds']} "
             f"rounds; states {meta['states']} (held out {meta['holdout']}). The gate's power floor: MAE before "
             f"{summ['power_floor_px']:.3f} px.", ""]
    for split in SPLITS:
        if split not in summ:
            continue
        s = summ[split]
        by_n = ", ".join(f"{n}: {_pct(v)}" for n, v in s["exact_named_by_n"].items())
        by_kind = ", ".join(f"{k}: {_pct(v)}" for k, v in s["out_of_list_unexplained_by_kind"].items())
        lines += [f"## {split} (seeds {s['seeds']}, {s['runs']} runs)", "",
                  f"* in-list runs ({s['in_list_runs']}): exact set named **{_pct(s['exact_named'])}** (by count of "
                  f"effects: {by_n or 'n/a'}); three-effect runs **{_pct(s['exact_named_3'])}**; exact and not "
                  f"`unexplained` {_pct(s['exact_and_clean'])}",
                  f"* against the identifiable truth (the oracle: each injected effect is needed by its data at the "
                  f"true parameters; {s['oracle_runs']} runs judged): exact {_pct(s['exact_identifiable'])}; not "
                  "identifiable: " + (", ".join(f"{e} {n}" for e, n in sorted(s["not_identifiable"].items())) or "none"),
                  f"* mean MAE cut on in-list runs: **{_pct(s['mae_cut_mean'])}**",
                  f"* `unexplained` on runs whose exact set was named: **{s['unexplained_on_exact']}** (on any in-list "
                  f"run: {s['in_list_unexplained']}); in-list runs below the gate's power: {s['below_power']}",
                  f"* outside runs ({s['out_of_list_runs']}): `unexplained` **{_pct(s['out_of_list_unexplained'])}** "
                  f"({by_kind or 'n/a'}); no physical effect named beyond the in-list truth "
                  f"**{_pct(s['out_of_list_no_extra'])}**",
                  f"* runs redrawn (their twin diverged): {s['redrawn']}",
                  "* per effect on in-list runs (named where injected; named where not): " + ", ".join(
                      f"{e} {v['found']}/{v['injected']}, spurious {v['spurious']}" for e, v in s["by_effect"].items()), ""]
    lines += ["## Runs", "", "| " + " | ".join(COLUMNS[:8]) + " |", "|" + "---|" * 8]
    for r in rows:
        lines.append("| " + " | ".join(_num(r[c]) if c.endswith(("_px", "_ratio")) else str(r[c])
                                       for c in COLUMNS[:8]) + " |")
    named = Counter(e for r in rows for e in r["named"])
    drawn = Counter(u for r in rows for u in r["unlisted"])
    lines += ["", "Named over all runs: " + (", ".join(f"{e} {n}" for e, n in named.most_common()) or "nothing")
              + "; outside kinds drawn: " + (", ".join(f"{u} {n}" for u, n in sorted(drawn.items())) or "none")
              + f". Outside effects are written `{UNLISTED_PREFIX}<kind>`; the true and fitted parameters are in "
              "loop_selftest_general.csv.", ""]
    return "\n".join(lines)


def write_outputs(out: Path, rows: list[dict], loop) -> dict:
    """loop_selftest_general.csv, selftest_general.md and .json in `out`; returns the summary."""
    g = loop.generative
    summ = summary(rows, g.noise_px, loop.method.gate_fit_rel)
    meta = {"fingerprint": rows[0]["fingerprint"] if rows else "none", "n_effects": list(g.n_effects), "E": list(g.E),
            "k_s": list(g.k_s), "unlisted_share": g.unlisted_share, "unlisted": sorted(g.unlisted),
            "noise_px": g.noise_px, "max_rounds": g.max_rounds, "states": list(loop.selftest.states),
            "holdout": list(loop.selftest.holdout)}
    save_text(Path(out) / "loop_selftest_general.csv", rows_csv(rows))
    save_text(Path(out) / "selftest_general.md", markdown(rows, summ, meta))
    save_json(Path(out) / "selftest_general.json", {"summary": summ, "settings": dataclasses.asdict(g), "runs": rows})
    return summ
