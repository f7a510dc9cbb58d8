"""Offline diagnosis of the generative self-test's spurious and missed effects (dev runs only; no twin runs).

    PYTHONPATH=src python workflow/scripts/loop_dev_diagnosis.py RUNS_DIR [--log RUN_LOG] [--csv SELFTEST_CSV]

RUNS_DIR holds the per-run records (generative/runs/*.json). The log (default RUNS_DIR/../../run.log, if present)
adds what the records leave out: each try's attribution share and fitted MAE before it, and the projected null's z.
--csv scores the parameter rules on a loop_selftest_general CSV too (no tries there). Prints markdown tables:
every kept effect with its evidence, every missed in-list effect, and per candidate rule the spurious and the true
effects it would remove. Journal: docs/journal/2026-11-29-loop-spurious-terms-diagnosis.md.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

import pandas as pd

from palpation.loop.effects import EFFECTS, PARAMS  # the twin's registry: bounds, log scale, off values

NOISE_MAE = 0.251  # sigma sqrt(pi/2), sigma = 0.2 px: the fitted MAE of a noise-only residual
LOG_FLOOR = 1e-12  # the log of a parameter at 0
TRY = re.compile(r"loop '(\S+)' round (\d+) try \d+: (\S+) explains ([\d.]+) % of the residual; MAE fit ([\d.]+) -> "
                 r"([\d.]+) px")
PROJ = re.compile(r"loop '(\S+)': (\S+) against its projected null .*?\(z = (-?[\d.]+)\)")
HELD = re.compile(r"held-out ([\d.]+) -> ([\d.]+) px \(z = (-?[\d.inf]+)\)")
CHALLENGE = re.compile(r"better than (\S+) \(held-out [\d.]+ -> [\d.]+ px \(z = (-?[\d.]+)\)")


def edge(name: str, value: float, effect: str) -> float:
    """Distance of a fitted value to the nearest search bound (or, for a one-parameter effect, its off value inside
    the bounds: a shell ratio of 1, the base damping), as a fraction of the (log) range."""
    p = PARAMS[name]
    f = (lambda x: math.log(max(x, LOG_FLOOR))) if p.log else (lambda x: x)
    marks = [p.low, p.high] + ([p.default] if len(EFFECTS[effect].params) == 1 and p.low < p.default < p.high else [])
    return min(abs(f(value) - f(m)) for m in marks) / (f(p.high) - f(p.low))


def read_log(path: Path | None) -> tuple[dict, dict]:
    tries, proj = {}, {}
    if path and path.exists():
        for line in path.read_text().splitlines():
            if m := TRY.search(line):
                tries[(m[1].split("_run")[1], int(m[2]), m[3])] = (float(m[4]), float(m[5]), float(m[6]))
            elif m := PROJ.search(line):
                proj[(m[1].split("_run")[1], m[2])] = float(m[3])
    return tries, proj


def kept_effects(runs_dir: Path, log: Path | None) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """One row per effect the rounds kept (with its try's evidence), one per in-list effect missed, and one per try
    refused although its held-out gain was significant (z >= 2)."""
    tries_log, proj = read_log(log)
    kept, missed, near = [], [], []
    for path in sorted(runs_dir.glob("*.json"), key=lambda p: int(p.stem.split("run")[1])):
        r = json.loads(path.read_text())
        run, inj = str(r["run"]), set(r["injected_effects"])
        fitted = json.loads(r["params_fitted"])
        z_off = {e: t["z_off"] for e, t in (r.get("parsimony") or {}).get("passes", [{}])[0].items()} \
            if (r.get("parsimony") or {}).get("passes") else {}
        base = {"run": int(run), "injected": r["effects_injected"], "excess": r["excess_ratio"],
                "unexplained": r["unexplained"], "outside": bool(r["unlisted"])}
        for e in r["named_by_rounds"]:
            t = next(t for t in r["tries"] if t["accepted"] and e in t["effects"])
            label = "+".join(t["effects"])
            h, c = HELD.search(t["why"]), CHALLENGE.search(t["why"])
            z_ch = float(c[2]) if c and e not in c[1].split("+") else None  # it came in by replacing a smaller winner
            share, fit0, fit1 = tries_log.get((run, t["round"], label), (None, None, t["fit_px"]))
            ps = {n: fitted[n] for n in EFFECTS[e].params if n in fitted}  # a spurious effect's are not recorded
            edges = [edge(n, v, e) for n, v in ps.items()]
            kept.append({**base, "effect": e, "true": e in inj, "dropped": e in r["parsimony"].get("dropped", []),
                         "round": t["round"], "set": label, "held0": float(h[1]), "held1": float(h[2]),
                         "z": float(h[3]),
                         "arm": "fit" if "within its noise" in t["why"].split(";")[0] else "held-out",
                         "share": share, "fit0": fit0, "fit1": fit1,
                         "excess_expl": (fit0 - fit1) / (fit0 - NOISE_MAE) if fit0 else None,
                         "z_ch": z_ch, "z_proj": proj.get((run, label)), "z_off": z_off.get(e),
                         "k_s": fitted.get("k_s") if e in ("surface_contact", "friction") else None,
                         "params": ", ".join(f"{n} {v:.4g}" for n, v in ps.items()),
                         "edge": min(edges) if edges else None})
        for t in r["tries"]:  # refused although the held-out was significantly better (the px and fit arms failed)
            h = HELD.search(t["why"])
            if not t["passed"] and not t["null_refused"] and h and float(h[3]) >= 2:
                near.append({"run": int(run), "round": t["round"], "set": "+".join(t["effects"]), "z": float(h[3]),
                             "true": " ".join(f"{e}:{e in inj}" for e in t["effects"]), "why": t["why"][:90]})
        for e in sorted(inj - set(r["named_by_rounds"])):
            best = [t for t in r["tries"] if e in t["effects"]]
            ps = ", ".join(f"{n} {fitted[n]:.4g}" for n in EFFECTS[e].params if n in fitted)
            missed.append({**base, "effect": e, "strength": r["strengths"].get(e), "params_fitted": ps,
                           "tries": " | ".join(f"r{t['round']} {'+'.join(t['effects'])}: {t['why'][:70]}"
                                               for t in best) or "never tried"})
    return pd.DataFrame(kept), pd.DataFrame(missed), pd.DataFrame(near)


RULES = {  # name: (description, predicate on a kept-effect row); rows without the evidence never fire
    "k_s<600": ("contact (and its friction) with k_s below the generative range's 600 N/m",
                lambda x: x.k_s is not None and x.k_s < 600),
    "k_s<300": ("contact (and its friction) with k_s below 300 N/m", lambda x: x.k_s is not None and x.k_s < 300),
    "edge<5%": ("a fitted parameter within 5 % of its (log) range of a bound or off value (where recorded)",
                lambda x: x.edge is not None and x.edge < 0.05),
    "z<2 arm": ("kept on the held-out-fall arm with z < 2 against the twin before",
                lambda x: x.arm == "held-out" and x.z < 2),
    "challenge z<2": ("came in with a larger set that replaced the round's winner with z < 2 against it",
                      lambda x: x.z_ch is not None and x.z_ch < 2),
    "above,expl<25%": ("round's fit MAE > 2x noise and the set explains < 25 % of the excess over the noise",
                       lambda x: x.fit0 is not None and x.fit0 > 2 * NOISE_MAE and x.excess_expl < 0.25),
    "above,share<20%": ("round's fit MAE > 2x noise and the set's attribution share < 20 %",
                        lambda x: x.fit0 is not None and x.fit0 > 2 * NOISE_MAE and x.share < 20),
    "unexpl,round>1": ("final check unexplained and the effect added after round 1",
                       lambda x: x.unexplained and x["round"] > 1),
    "unexpl,z_off<5": ("final check unexplained and switching it off at the end gives z < 5",
                       lambda x: x.unexplained and x.z_off is not None and x.z_off < 5),
}


def score(kept: pd.DataFrame, only=None) -> pd.DataFrame:
    rows = []
    live = kept[~kept.dropped]  # what the inert verdict already took out is not counted
    for name, (desc, rule) in RULES.items():
        if only and name not in only:
            continue
        hit = live[live.apply(rule, axis=1)]
        sp, tr = hit[~hit.true], hit[hit.true]
        rows.append({"rule": name, "spurious removed": f"{len(sp)} of {int((~live.true).sum())}",
                     "true removed": f"{len(tr)} of {int(live.true.sum())}",
                     "spurious": " ".join(f"{r.run}:{r.effect}" for r in sp.itertuples()),
                     "true": " ".join(f"{r.run}:{r.effect}" for r in tr.itertuples()), "what": desc})
    return pd.DataFrame(rows)


def csv_effects(path: Path) -> pd.DataFrame:
    """Kept effects of a summary CSV (no tries): truth, k_s, the fitted parameters' edge where recorded."""
    rows = []
    for r in pd.read_csv(path).itertuples():
        inj = set(r.effects_injected.split("+")) - {"none"}
        named = [e for e in r.effects_named.split("+") if e not in ("none", "unexplained")]
        fitted = json.loads(r.params_fitted)
        for e in named:
            ps = {n: fitted[n] for n in EFFECTS[e].params if n in fitted}
            edges = [edge(n, v, e) for n, v in ps.items()]
            rows.append({"run": r.run, "effect": e, "true": e in inj, "dropped": False,
                         "k_s": fitted.get("k_s") if e in ("surface_contact", "friction") else None,
                         "edge": min(edges) if edges else None, "arm": None, "z": None, "fit0": None, "share": None,
                         "excess_expl": None})
    return pd.DataFrame(rows)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("runs", type=Path)
    ap.add_argument("--log", type=Path)
    ap.add_argument("--csv", type=Path)
    a = ap.parse_args()
    kept, missed, near = kept_effects(a.runs, a.log or a.runs.parent.parent / "run.log")
    pd.set_option("display.width", 250)
    cols = ["run", "effect", "true", "dropped", "round", "set", "held0", "held1", "z", "arm", "share", "fit0", "fit1",
            "excess_expl", "z_ch", "z_proj", "z_off", "excess", "params", "edge"]
    bad = kept[~kept.true | kept.run.isin(kept[~kept.true].run)]
    print("## kept effects on runs with a spurious one\n", bad[cols].round(3).to_markdown(index=False))
    print("\n## missed in-list effects\n", missed.round(3).to_markdown(index=False))
    print("\n## refused tries with held-out z >= 2\n", near.to_markdown(index=False))
    print("\n## every kept effect\n", kept[cols].round(3).to_markdown(index=False))
    print("\n## rules (records)\n", score(kept).to_markdown(index=False))
    if a.csv:
        c = csv_effects(a.csv)
        table = score(c, only=("k_s<600", "k_s<300", "edge<5%"))
        print(f"\n## rules ({a.csv.name}; parameter rules only)\n", table.to_markdown(index=False))
        print("\ncontact named:", c[c.effect == "surface_contact"][["run", "true", "k_s"]].to_string(index=False))
