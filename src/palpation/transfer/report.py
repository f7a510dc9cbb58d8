"""The transfer table (docs/results/transfer.csv): per configuration, method and selection rule, the scored set's
metrics over seeds and whether the rule chose the method (docs/transfer.md).

Rows come only from run records (palpation.transfer.selection.Run): nothing is written without every listed seed's
run. `chosen` is true on one row per (config, selection, transductive): inductive and transductive methods are
chosen apart, as they are reported apart. Beside the CSV, a JSON gives each row's selection score and the data it
was computed on.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from palpation.config_ranges import Choice, ListOf, Text
from palpation.io import csv_text, save_json, save_text
from palpation.metrics.calibration import positive_share
from palpation.metrics.classification import marker_metrics
from palpation.metrics.scores import Scores
from palpation.model.domain import other_real_set, partner_name
from palpation.readers import read_yaml
from palpation.report.runs import run_dir
from palpation.transfer.selection import SELECTIONS, Run, choose, crossfit_by_trials, read_run, selection_score

COLUMNS = ("config", "method", "selection", "transductive", "chosen", "seeds", "ap_mean", "ap_std", "auroc_mean",
           "pos_share_05")
CONFIGS = ("A-to-B", "A-to-C", "C-to-B")  # the transfer configurations (conf/experiment/)
METHOD_KEYS = {"about": Text(), "transductive": Choice(True, False), "overrides": ListOf(Text(), 0)}
OPTIONAL_KEYS = {"configs": ListOf(Choice(*CONFIGS), 1, unique=True),  # default: every configuration
                 "scored_with": Text()}  # another method whose models it scores, its own alignment aside
ALIGN_KEYS = ("recipe.align=", "recipe.align_stats=")  # overrides applied at scoring only (docs/transfer.md)


def read_methods(path: str | Path) -> dict[str, dict]:
    """conf/transfer/methods.yaml: `methods: {name: {about, transductive, overrides[, configs, scored_with]}}`;
    unknown keys refused. `configs`: the configurations the method runs on (a self-trained student has no inductive
    C-to-B). `scored_with`: a method (without scored_with) whose overrides are this one's but for the alignment
    (ALIGN_KEYS): its trainings score this method too (train app `also_aligned`), so the two share their models."""
    fix = (f"edit {path} (docs/transfer.md: a method is about, transductive, overrides and optionally configs and "
           "scored_with)")
    data = read_yaml(path, fix, "transfer methods")
    methods = data.get("methods") if set(data) == {"methods"} else None
    if not isinstance(methods, dict) or not methods:
        raise ValueError(f"{path}: one top-level key `methods`, a non-empty mapping of method names; {fix}")
    for name, spec in methods.items():
        if not isinstance(spec, dict) or not set(METHOD_KEYS) <= set(spec) <= {*METHOD_KEYS, *OPTIONAL_KEYS}:
            raise ValueError(f"{path}: method {name!r} needs exactly the keys {sorted(METHOD_KEYS)} (and optionally "
                             f"{sorted(OPTIONAL_KEYS)}); {fix}")
        for key, rule in {**METHOD_KEYS, **OPTIONAL_KEYS}.items():
            if key in spec and rule.problem(spec[key]):
                raise ValueError(f"{path}: methods.{name}.{key}={spec[key]!r}: need {rule.describe()}; {fix}")
    for name, spec in methods.items():
        if "scored_with" in spec and scoring_problem(methods, name):
            raise ValueError(f"{path}: methods.{name}.scored_with={spec['scored_with']!r}: "
                             f"{scoring_problem(methods, name)}; {fix}")
    return methods


def without_alignment(overrides: list[str]) -> list[str]:
    return [o for o in overrides if not o.startswith(ALIGN_KEYS)]


def alignment_of(overrides: list[str]) -> tuple[str, str]:
    """(align, align_stats) a method's overrides set (the recipe's defaults where unset)."""
    got = dict(o.split("=", 1) for o in overrides if o.startswith(ALIGN_KEYS))
    return got.get("recipe.align", "none"), got.get("recipe.align_stats", "other_real")


def scoring_problem(methods: dict, name: str) -> str | None:
    """Why `name` cannot be scored with its `scored_with` method's models, or None."""
    base = methods[name]["scored_with"]
    if base not in methods or "scored_with" in methods[base]:
        return "name a method of this file that has no scored_with itself"
    if without_alignment(methods[name]["overrides"]) != without_alignment(methods[base]["overrides"]):
        return f"its overrides must be {base}'s but for {' / '.join(k[:-1] for k in ALIGN_KEYS)}"
    if alignment_of(methods[name]["overrides"])[0] == "none":
        return "it must set recipe.align (otherwise it is the same method)"
    if any(not covers(methods[base], c) for c in CONFIGS if covers(methods[name], c)):
        return f"it may run only on configurations {base} runs on"
    return None


def is_transductive(method: str, spec: dict, runs: list[Run]) -> bool:
    """The declared flag, checked against the runs: an alignment on, or self-training with, the scored set's own
    clips is transductive."""
    used = any(r.metrics.get(k, {}).get("transductive", False) for r in runs for k in ("alignment", "pseudo_labels"))
    if used and not spec["transductive"]:
        raise ValueError(f"method {method}: its runs read the scored set's own clips (alignment or pseudo-labels, "
                         f"{runs[0].path}); declare it transductive: true")
    return bool(spec["transductive"])


def covers(spec: dict, config: str) -> bool:
    """Whether a method runs on `config` (its `configs`, every configuration by default)."""
    return "configs" not in spec or config in spec["configs"]


def summary(scores: list[tuple[np.ndarray, np.ndarray]]) -> dict:
    """Mean / sample std of AP, mean AUROC and mean share of markers at >= 0.5 over seeds' (probs, labels)."""
    m = [marker_metrics(p, lab) for p, lab in scores]
    ap = np.array([x["ap"] for x in m])
    return {"seeds": len(scores), "ap_mean": float(ap.mean()), "ap_std": float(ap.std(ddof=1)) if len(ap) > 1 else 0.0,
            "auroc_mean": float(np.mean([x["auroc"] for x in m])),
            "pos_share_05": float(np.mean([positive_share(p) for p, _ in scores]))}


def _scored(runs: list[Run]) -> list[Scores]:
    return [r.scores() for r in runs]


def table(root: str | Path, methods: dict[str, dict], configs: list[str], seeds: list[int], clip_len: int,
          crossfit: dict[str, int] | None = None) -> list[dict]:
    """The rows (COLUMNS plus `selection_score` and `chosen_on`, the JSON's details). `crossfit`: configurations whose cross_real choice is cross-fitted by trials on the
    scored set itself (n folds), for a set that must both choose and be scored."""
    crossfit, every = crossfit or {}, methods
    runs = {(m, c): [read_run(root, m, c, clip_len, s) for s in seeds] for m in every for c in configs
            if covers(every[m], c)}
    by_method = {m: [r for c in configs if (m, c) in runs for r in runs[(m, c)]] for m in every}
    for m in every:  # a configuration left out of the rows may still hold a run's cross_real partner (A-to-C)
        for c in [c for c in CONFIGS if c not in configs and covers(every[m], c)]:
            if all((run_dir(Path(root) / m, c, clip_len, s) / "metrics.json").is_file() for s in seeds):
                by_method[m] += [read_run(root, m, c, clip_len, s) for s in seeds]
    for (m, c), rs in runs.items():  # the cross_real partners of runs that chose on the other set's selection half
        if rs[0].metrics.get("selected_on", "").endswith(" half"):
            partner = partner_name(c, other_real_set(rs[0].metrics["test_on"]))
            by_method[m] += [read_run(root, m, partner, clip_len, s) for s in seeds]
    rows = []
    for config in configs:
        methods = {m: spec for m, spec in every.items() if covers(spec, config)}
        scored = {m: _scored(runs[(m, config)]) for m in methods}
        flag = {m: is_transductive(m, methods[m], runs[(m, config)]) for m in methods}
        base = {m: summary([(s.probs, s.labels) for s in scored[m]]) for m in methods}
        for selection in SELECTIONS:
            if selection == "cross_real" and config in crossfit:
                rows += _crossfit_rows(config, methods, scored, flag, base, crossfit[config])
                continue
            score = {m: [selection_score(r, selection, by_method[m]) for r in runs[(m, config)]] for m in methods}
            if all(any(v is None for v in vals) for vals in score.values()):
                continue  # the rule scores no method here (sim_val of a Meat-trained configuration)
            means = {m: None if any(v is None for v in vals) else [v[0] for v in vals] for m, vals in score.items()}
            picked = {t: choose({m: means[m] for m in methods if flag[m] == t}) for t in (False, True)}
            for m in methods:
                rows.append({"config": config, "method": m, "selection": selection, "transductive": flag[m],
                             "chosen": picked[flag[m]] == m, **base[m],
                             "selection_score": None if means[m] is None else float(np.mean(means[m])),
                             "chosen_on": sorted({v[1] for v in score[m] if v is not None})})
    return rows


def _crossfit_rows(config, methods, scored, flag, base, n_folds) -> list[dict]:
    rows = [{"config": config, "method": m, "selection": "cross_real", "transductive": flag[m], "chosen": False,
             **base[m], "selection_score": None, "chosen_on": []} for m in methods]
    for t in (False, True):
        group = {m: scored[m] for m in methods if flag[m] == t}
        if not group:
            continue
        fit = crossfit_by_trials(group, n_folds)
        rows.append({"config": config, "method": "crossfit(" + "|".join(fit["choices"]) + ")",
                     "selection": "cross_real", "transductive": t, "chosen": True, **summary(fit["scores"]),
                     "selection_score": None, "chosen_on": [f"{config} trials {f} (other folds)" for f in fit["folds"]]})
    return rows


def write_table(rows: list[dict], out_csv: str | Path, left_out: list[str] = ()) -> None:
    """The CSV (COLUMNS, 4 decimals) and `<stem>.json` beside it with every row's selection details (and the
    methods whose rows were left out, where any were)."""
    out_csv = Path(out_csv)
    shown = [{**r, "transductive": str(r["transductive"]).lower(), "chosen": str(r["chosen"]).lower()} for r in rows]
    save_text(out_csv, csv_text(shown, COLUMNS, 4))
    record = {"columns": list(COLUMNS), "rows": rows}
    if left_out:
        record["left_out"] = list(left_out)
    save_json(out_csv.with_suffix(".json"), record)
