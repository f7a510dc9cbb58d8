"""The residual loop's numbers in the docs: the real photos' loop tables and the self-tests' measures.

The self-tests' measures are those of loop.selftest.fixed.summary and loop.selftest.generative_report.split_summary,
recomputed from the CSV they write (importing the loop would import the twin). Registered in report.docnumbers.
"""

from __future__ import annotations

import json
import re
from datetime import datetime
from pathlib import Path
from typing import Callable

from palpation.readers import read_text
from palpation.report.compare import truthy
from palpation.report.records import FIX, record_csv as _csv


def loop_change(results: Path, column: str, unit: str, digits: int, name: str = "loop_real.csv") -> str:
    """First round → last round of the residual loop on the real photos (loop_real.csv)."""
    values = _csv(results, name, ("round", column)).sort_values("round")[column]
    return f"{values.iloc[0]:.{digits}f} → {values.iloc[-1]:.{digits}f} {unit}"


def loop_last(results: Path, column: str, unit: str, digits: int, name: str) -> str:
    """The last round's value of a residual-loop table."""
    values = _csv(results, name, ("round", column)).sort_values("round")[column]
    return f"{values.iloc[-1]:.{digits}f} {unit}"


def loop_effects(results: Path, name: str = "loop_real.csv") -> str:
    effects = _csv(results, name, ("round", "effect_added")).sort_values("round")["effect_added"]
    return ", then ".join(f"`{e}`" for e in effects if e != "none")


def loop_same_table(results: Path, a: str, b: str) -> str:
    """Whether two runs of the real-photo loop wrote the same table (their CSVs at the records' 4 decimals)."""
    cols = ("round", "effect_added", "mae_fit_px", "mae_heldout_px", "mae_mean_mm")
    ta, tb = (_csv(results, n, cols).fillna("") for n in (a, b))
    if ta.astype(str).equals(tb.astype(str)):
        return "the same table to the fourth decimal"
    return (f"another table (held-out {loop_change(results, 'mae_heldout_px', 'px', 4, b)} against "
            f"{loop_change(results, 'mae_heldout_px', 'px', 4, a)})")


def loop_rest_ratio(results: Path, name: str) -> str:
    """The final residual against the detector noise, as the loop's report.md states it: only Markdown holds it,
    so it is read from the verdict's one line "beyond the final twin's own parameters N× the noise" (or, under
    loop.method.unexplained_beyond=candidates, "the rest is N× the noise"; an error if that line is gone)."""
    text = read_text(results / name, FIX, "record")
    found = re.findall(r"(?:the rest is|beyond the final twin's own parameters) ([0-9]+(?:\.[0-9]+)?)\s*×\s*the noise",
                       text)
    if len(found) != 1:
        raise ValueError(f"record {results / name}: expected one 'N× the noise' line in the verdict, found {len(found)}")
    return f"{found[0]}×"


def loop_target(results: Path, name: str) -> str:
    """The accuracy target's verdict, as the loop's report.md states it: only Markdown holds it, so it is read
    from the verdict's one line "Target (...): mean X mm against Y mm: met|missed" (an error if that line is gone)."""
    text = read_text(results / name, FIX, "record")
    found = re.findall(r"^\* Target [^:]*: mean [0-9.]+ mm against ([0-9.]+) mm: (met|missed)", text, re.M)
    if len(found) != 1:
        raise ValueError(f"record {results / name}: expected one '* Target ...: met|missed' line, found {len(found)}")
    return f"target ≤ {found[0][0]} mm {found[0][1]}"


# --- the residual loop's self-tests: the measures of loop.selftest.fixed.summary and
# loop.selftest.generative_report.split_summary, recomputed from the CSV they write (importing the loop would
# import the twin); a run's effects are '+'-joined, an outside one `unlisted:<kind>`, `unexplained` a verdict.

def _effects(cell) -> list[str]:
    return [e for e in str(cell).split("+") if e and e not in ("none", "nan")]


def selftest_runs(results: Path, name: str) -> list[dict]:
    table = _csv(results, name, ("run", "effects_injected", "effects_named", "mae_before_px", "mae_after_px"))
    runs = []
    for r in table.to_dict("records"):
        injected, named = _effects(r["effects_injected"]), _effects(r["effects_named"])
        runs.append({**r, "injected": {e for e in injected if not e.startswith("unlisted:")},
                     "unlisted": any(e.startswith("unlisted:") for e in injected),
                     "named": set(named) - {"unexplained"}, "unexplained": "unexplained" in named})
    return runs


def _pct(x: float) -> str:
    return f"{100 * x:.0f} %"


def _share(flags: list[bool]) -> float:
    if not flags:
        raise ValueError("a self-test record without the runs a measure needs; regenerate the record")
    return sum(flags) / len(flags)


def fixed_exact(runs: list[dict]) -> list[bool]:
    """Fixed list: the in-list set named, no more and no less, and not `unexplained` (in-list runs)."""
    return [r["named"] == r["injected"] and not r["unexplained"] for r in runs if not r["unlisted"]]


def fixed_exact_share(results: Path, name: str) -> str:
    return _pct(_share(fixed_exact(selftest_runs(results, name))))


def fixed_summary(results: Path, name: str) -> str:
    """The fixed-list self-test's aims: exact set, MAE cut (in-list), outside runs `unexplained`, in-list ones."""
    runs = selftest_runs(results, name)
    inl = [r for r in runs if not r["unlisted"]]
    out = [r for r in runs if r["unlisted"]]
    cut = [1 - r["mae_after_px"] / r["mae_before_px"] for r in inl if r["mae_before_px"] > 0]
    return (f"exact in-list set {_pct(_share(fixed_exact(runs)))} of {len(inl)}, MAE cut {_pct(_share(cut))}, "
            f"out-of-list `unexplained` {_pct(_share([r['unexplained'] for r in out]))} of {len(out)}, in-list "
            f"`unexplained` {sum(r['unexplained'] for r in inl)}")


def fixed_inlist_unexplained(results: Path, names: tuple[str, ...]) -> str:
    return " + ".join(str(sum(r["unexplained"] for r in selftest_runs(results, n) if not r["unlisted"]))
                      for n in names)


def reduced_mae_after(results: Path, before: str, after: str) -> str:
    """Mean MAE after the loop over a reduced self-test's runs, before → after a change of the method."""
    values = [sum(r["mae_after_px"] for r in runs) / len(runs)
              for runs in (selftest_runs(results, before), selftest_runs(results, after))]
    return f"{values[0]:.2f} → {values[1]:.2f} px"


def reduced_run_after(results: Path, before: str, after: str, injected: str) -> str:
    """One run's MAE after the loop (the run that injected `injected`), before → after a change of the method."""
    values = []
    for n in (before, after):
        found = [r["mae_after_px"] for r in selftest_runs(results, n) if r["effects_injected"] == injected]
        if len(found) != 1:
            raise ValueError(f"record {results / n}: {len(found)} runs injected {injected}, expected one")
        values.append(found[0])
    return f"{values[0]:.2f} → {values[1]:.2f} px"


def reduced_converged(results: Path, before: str, after: str) -> str:
    runs = [selftest_runs(results, n) for n in (before, after)]
    exact = [sum(fixed_exact(r)) for r in runs]
    unexplained = [sum(x["unexplained"] for x in r if not x["unlisted"]) for r in runs]
    return (f"{exact[0]} → {exact[1]} of {len(fixed_exact(runs[1]))} exact, in-list `unexplained` "
            f"{unexplained[0]} → {unexplained[1]}")


def general_exact(runs: list[dict], n: int | None = None) -> list[bool]:
    """Generative: the in-list set named, no more and no less (`unexplained` aside), on in-list runs (of n effects)."""
    return [r["named"] == r["injected"] for r in runs
            if not r["unlisted"] and (n is None or len(r["injected"]) == n)]


def general_summary(results: Path, name: str) -> str:
    runs = selftest_runs(results, name)
    inl = [r for r in runs if not r["unlisted"]]
    out = [r for r in runs if r["unlisted"]]
    three = general_exact(runs, 3)
    cut = [1 - r["mae_after_px"] / r["mae_before_px"] for r in inl if r["mae_before_px"] > 0]
    n_unexplained = sum(r["unexplained"] for r in inl)
    verdict = (f"`unexplained` on {n_unexplained} in-list runs" if n_unexplained
               else "no `unexplained` on an in-list run")
    outside = (f"outside runs `unexplained` {sum(r['unexplained'] for r in out)} of {len(out)}, nothing named beyond "
               f"the truth in {sum(r['named'] <= r['injected'] for r in out)} of {len(out)}")
    return (f"exact in-list set **{_pct(_share(general_exact(runs)))}** of {len(inl)} (three-effect runs "
            f"{sum(three)} of {len(three)}), MAE cut {_pct(_share(cut))}, {verdict}; {outside}")


def general_brief(results: Path, name: str) -> str:
    """The README's line on a generative test record: the exact in-list set and the outside effects flagged."""
    runs = selftest_runs(results, name)
    inl, out = [r for r in runs if not r["unlisted"]], [r for r in runs if r["unlisted"]]
    return (f"names the exact effect set in {_pct(_share(general_exact(runs)))} of {len(inl)} in-list runs and calls "
            f"{_pct(_share([r['unexplained'] for r in out]))} of {len(out)} outside effects `unexplained`")


def general_exact_of(results: Path, name: str) -> str:
    exact = general_exact(selftest_runs(results, name))
    return f"{_pct(_share(exact))} of {len(exact)}"


def general_shared(results: Path, earlier: str, later: str) -> str:
    """Exact in-list runs of two measurements on the runs (seed, run) they share: earlier → later of n."""
    a, b = ({(r["seed"], r["run"]): r for r in selftest_runs(results, n)} for n in (earlier, later))
    keys = [k for k in sorted(set(a) & set(b)) if not a[k]["unlisted"]]
    if not keys:
        raise ValueError(f"records {earlier} and {later} share no in-list run")
    return (f"{sum(general_exact([a[k] for k in keys]))} → {sum(general_exact([b[k] for k in keys]))} of "
            f"{len(keys)} exact")


def general_below_power(results: Path, name: str) -> str:
    """In-list runs with effects whose MAE before lies under the gate's power floor, the floor as the run's
    selftest_general.md states it (only Markdown holds it: "The gate's power floor: MAE before X px")."""
    text = read_text(results / name.replace(".csv", ".md"), FIX, "record")
    found = re.findall(r"power floor: MAE before ([0-9.]+) px", text)
    if len(found) != 1:
        raise ValueError(f"record {results / name.replace('.csv', '.md')}: no single 'power floor' line")
    runs = [r for r in selftest_runs(results, name) if not r["unlisted"] and r["injected"]]
    return str(sum(r["mae_before_px"] < float(found[0]) for r in runs))


def general_soft_e(results: Path, name: str, injected: str) -> str:
    """The run that injected `injected`: its residual against the noise, its fitted and its true E."""
    table = _csv(results, name, ("effects_injected", "excess_ratio", "params_true", "params_fitted"))
    rows = table[table["effects_injected"] == injected]
    if len(rows) != 1:
        raise ValueError(f"record {results / name}: {len(rows)} runs injected {injected}, expected one")
    r = rows.iloc[0]
    fitted, true = json.loads(r["params_fitted"])["E"], json.loads(r["params_true"])["E"]
    return f"{r['excess_ratio']:.1f}× the noise: E {fitted / 1e6:.2f} against {true / 1e6:.2f} MPa"


def general_by_effect(results: Path, name: str, effect: str) -> str:
    """One effect over the in-list runs: named where injected, and named where not (spurious)."""
    inl = [r for r in selftest_runs(results, name) if not r["unlisted"]]
    has = [r for r in inl if effect in r["injected"]]
    spurious = sum(effect in r["named"] and effect not in r["injected"] for r in inl)
    return f"{sum(effect in r['named'] for r in has)} of {len(has)} (spurious in {spurious} of {len(inl) - len(has)})"


def general_wall(results: Path, log_name: str) -> str:
    """The generative self-test's saved batches as its log times them: their runs, from the start line to the last
    "runs [...] saved" (a batch the run did not finish is not counted)."""
    stamps = re.findall(r"^\[(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d),\d+\]\[[\w.]+\]\[INFO\] - generative self-test"
                        r"(?::)? (?:runs \[(.*?)\] saved|\()", read_text(results / log_name, FIX, "record"), re.M)
    if len(stamps) < 2 or stamps[0][1]:
        raise ValueError(f"record {results / log_name}: no start line followed by a 'runs [...] saved' line")
    start = datetime.fromisoformat(stamps[0][0])
    saved = [(datetime.fromisoformat(t), runs.count("'") // 2) for t, runs in stamps[1:] if runs]
    end, n = saved[-1][0], sum(k for _, k in saved)
    return f"{n} runs in {(end - start).total_seconds():.0f} s"


def general_oracle(results: Path, md_name: str) -> str:
    """The exact set against the oracle's identifiable truth, as the self-test's page states it (only the page and
    the JSON hold the oracle: the CSV keeps the issue's columns)."""
    text = read_text(results / md_name, FIX, "record")
    found = re.findall(r"^\* against the identifiable truth .*?; (\d+) runs judged\): exact (\d+%); not identifiable: "
                       r"(.*)$", text, re.M)
    if len(found) != 1:
        raise ValueError(f"record {results / md_name}: no single 'against the identifiable truth' line; make the "
                         "page again with the oracle (resume the self-test)")
    runs, exact, missing = found[0]
    return f"exact {exact.replace('%', ' %')} of {runs} judged runs (not identifiable: {missing})"


def general_split(stem: str, log_name: str, effects: tuple[str, ...] = ("layered", "mount", "friction")
                  ) -> dict[str, Callable[[Path], str]]:
    """The doc keys of one generative test record (<stem>.csv, its page <stem>.md and its log): size, summary,
    oracle, wall time and the named `effects`."""
    csv, md = f"{stem}.csv", f"{stem}.md"
    keys = {"_runs": lambda r: str(len(selftest_runs(r, csv))), "": lambda r: general_summary(r, csv),
            "_oracle": lambda r: general_oracle(r, md), "_wall": lambda r: general_wall(r, log_name)}
    for effect in effects:
        keys[f"_{effect}"] = lambda r, e=effect: general_by_effect(r, csv, e)
    return keys


def dev_choice(results: Path, name: str) -> str:
    """A dev comparison of the default loop and one changed method (workflow/scripts/loop_dev_choice.py)."""
    record = json.loads(read_text(results / name, FIX, "record"))
    a, b = record["counts"]["default"], record["counts"]["changed"]
    return (f"exact {a['exact']} → {b['exact']} of {a['in_list']}, outside `unexplained` {a['outside_unexplained']} → "
            f"{b['outside_unexplained']} and nothing beyond the truth {a['outside_clean']} → {b['outside_clean']} of "
            f"{a['outside']} (chosen: {record['choice']})")


def verdict_rescore(results: Path, name: str) -> str:
    """The final check's two rules on the same final twins (workflow/scripts/loop_verdict_rescore.py)."""
    table = _csv(results, name, ("unlisted", "exact", "unexplained_twin", "unexplained_candidates"))
    out = table[table["unlisted"].fillna("") != ""]
    exact = table[(table["unlisted"].fillna("") == "") & table["exact"]]
    return (f"outside runs flagged {int(out['unexplained_candidates'].sum())} → {int(out['unexplained_twin'].sum())} "
            f"of {len(out)}, runs with the exact set flagged {int(exact['unexplained_candidates'].sum())} → "
            f"{int(exact['unexplained_twin'].sum())} of {len(exact)}")


def bench_loop(results: Path, name: str) -> str:
    """A loop benchmark record (workflow/scripts/bench_loop.py): its wall time and the cores it had."""
    record = json.loads(read_text(results / name, FIX, "record"))
    return (f"{record['wall_s']:.0f} s wall ({record['twin_s']:.0f} s in the twin) on {record['cpu_affinity']} of "
            f"{record['cpu_count']} cores")


def strength_floor(results: Path, name: str, floor: float = 0.1) -> str:
    """What the verdict's strength floor takes out of the dev records (workflow/scripts/loop_strength_floor.py)."""
    table = _csv(results, name, ("record", "effect", "injected", "strength_fitted"))
    true, spurious = table[table["injected"]], table[~table["injected"]]
    harm = int((true["strength_fitted"] < floor).sum())
    return (f"of {len(true)} injected effects named, the smallest fitted at {true['strength_fitted'].min():.2f} "
            f"steps, {harm or 'none'} below the floor; of {len(spurious)} spurious ones, "
            f"{int((spurious['strength_fitted'] < floor).sum())} taken out, over {table['record'].nunique()} records")


def verdict_ratio(results: Path, name: str) -> str:
    """The verdict's ratio chosen on the dev records, against the earlier 2 (workflow/scripts/loop_verdict_ratio.py)."""
    t = _csv(results, name, ("ratio", "exact_runs", "exact_flagged", "outside_runs", "outside_flagged",
                             "inexact_runs", "inexact_flagged", "chosen")).set_index("ratio")
    c, old = t[t["chosen"].map(truthy)].iloc[0], t.loc[2.0]
    return (f"{c.name:g} chosen; against 2, runs with the exact set flagged {old['exact_flagged']} → "
            f"{c['exact_flagged']} of {c['exact_runs']}, outside runs {old['outside_flagged']} → {c['outside_flagged']} "
            f"of {c['outside_runs']}, other in-list runs {old['inexact_flagged']} → {c['inexact_flagged']} of "
            f"{c['inexact_runs']}")


def shell_vs_e(results: Path, name: str) -> str:
    """The thick shell's signature outside E's, on the quick fit states and with the slide
    (workflow/scripts/loop_shell_separation.py)."""
    sets = json.loads(read_text(results / name, FIX, "record"))["sets"]
    share = {k: v["columns"]["layered.shell_ratio"]["outside_E"] for k, v in sets.items()}
    fit, slide = share["quick fit states (press, twist_z, twist_x)"], share["quick fit states + slide"]
    return f"{100 * fit:.1f} % of its column lies outside E's on the fitted states, {100 * slide:.1f} % with the slide"


LOOP_DEV_KEYS = {  # docs/loop.md: what the dev measurements chose or showed (records of dev seeds only)
    "loop.general.attribution": lambda r: dev_choice(r, "loop_dev_attribution.json"),
    "loop.general.verdict": lambda r: verdict_rescore(r, "loop_verdict_rescore_dev.csv"),
    "loop.general.null_escape": lambda r: dev_choice(r, "loop_dev_null_escape.json"),
    "loop.general.strength_floor": lambda r: strength_floor(r, "loop_strength_floor_dev.csv"),
    "loop.shell_vs_e": lambda r: shell_vs_e(r, "loop_shell_separation_dev.json"),
    "loop.general.verdict_ratio": lambda r: verdict_ratio(r, "loop_verdict_ratio_dev.csv"),
}
