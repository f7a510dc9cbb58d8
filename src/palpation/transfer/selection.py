"""Which data chooses a transfer method (docs/transfer.md): the selection rules of the transfer table.

A *method* is a set of training-run switches (conf/transfer/methods.yaml); its runs are per-seed folders
`<root>/<method>/<config>/L<n>/seed<s>/` (metrics.json, scores.npz: what palpation.apps.train writes with
hydra.run.dir=<root>/<method>/<config>/L<n> and seeds=[...]). Per configuration, each rule gives every method a
score from data other than the scored set, and the method with the highest mean over seeds is chosen:

* `sim_val`: the run's best-epoch AP on the Sim validation split (history `val/ap`; Sim-trained runs whose
  checkpoint was chosen there);
* `cross_real`: AP on the labelled real set that the run is not scored on, on its *method half* of trials
  (model.domain.half_trials), from the same models' scores on that set (A-to-B's models scored on Meat as A-to-C,
  trained together: also_test; a run that chose its checkpoint on the other half, select_on=other_real_half, scores
  it as its partner `<config>.on_<set>`); a Meat-trained run (C-to-B), whose every method chose on the Meat val
  trials alike, by that checkpoint split's AP. A run that chose on every trial of the other set is refused.

A scored set's labels are never read here: the scored run's own scores.npz is read only by the report. Where one
set must both choose and be scored, `crossfit_by_trials` chooses for each fold of its trials on the other folds.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sklearn.metrics import average_precision_score

from palpation.metrics.scores import Scores, load_scores
from palpation.model.domain import half_trials, other_real_set, partner_name
from palpation.readers import read_json
from palpation.report.runs import run_dir

SELECTIONS = ("sim_val", "cross_real")


@dataclass(frozen=True)
class Run:
    """One seed's record of one (method, configuration)."""

    method: str
    config: str
    seed: int
    metrics: dict
    path: Path  # its folder

    def scores(self) -> Scores:
        return load_scores(self.path / "scores.npz")


def read_run(root: str | Path, method: str, config: str, clip_len: int, seed: int) -> Run:
    path = run_dir(Path(root) / method, config, clip_len, seed)
    metrics = read_json(path / "metrics.json", "run the method's training (docs/transfer.md, the commands)",
                        f"{method} run", kind=dict, keys=("config", "train_on", "test_on", "best_epoch", "history"))
    return Run(method, config, seed, metrics, path)


def val_ap(run: Run) -> float:
    """The best epoch's AP on the run's checkpoint split (logged with select_metric=ap)."""
    row = run.metrics["history"][run.metrics["best_epoch"]]
    if "val/ap" not in row:
        raise ValueError(f"{run.path}: no val/ap in its history; train the method with recipe.select_metric=ap so "
                         "the selection rules can compare its checkpoint split's AP")
    return float(row["val/ap"])


def checkpoint_split(run: Run) -> str:
    """'<set> val' or '<set> all': the split that chose the run's checkpoint (metrics.json `selected_on`)."""
    return run.metrics.get("selected_on", f"{run.metrics['train_on']} val")


def same_models(a: Run, b: Run) -> bool:
    """True when two runs' scores come from one training (trained together: one seed, both configurations)."""
    ta, tb = a.metrics.get("trained_together", {}), b.metrics.get("trained_together", {})
    return a.seed == b.seed and bool(ta) and ta == tb and {a.config, b.config} <= set(ta.get("configs", ()))


def selection_score(run: Run, selection: str, runs: list[Run]) -> tuple[float, str] | None:
    """(score, what it was computed on) of `run` under a rule, None where the rule cannot score it. `runs`: the
    other runs of the same method (where a cross_real partner is looked up)."""
    m = run.metrics
    if selection == "sim_val":
        return (val_ap(run), "sim val") if checkpoint_split(run) == "sim val" else None
    if selection != "cross_real":
        raise ValueError(f"unknown selection {selection!r}: use one of {list(SELECTIONS)}")
    other = other_real_set(m["test_on"])
    split = checkpoint_split(run)
    if split == f"{other} val":  # a Meat-trained run: every method chose on the Meat val trials alike
        return val_ap(run), split
    if split == f"{other} all":
        raise ValueError(f"{run.path}: its checkpoint was chosen on every {other} trial, the method half that the "
                         f"cross_real rule scores on included; train it with recipe.select_on=other_real_half")
    partners = [r for r in runs if r.method == run.method and r.metrics["test_on"] == other and same_models(run, r)]
    if not partners:
        raise ValueError(f"{run.path}: cross_real needs the same models scored on {other} (train {run.config} with "
                         f"also_test=[<config>:{other}], or [{partner_name(run.config, other)}:{other}] beside "
                         "recipe.select_on=other_real_half)")
    s = partners[0].scores()
    method_half = half_trials(np.unique(s.sequence).tolist())[1]  # the set loads sorted: indices order as trials
    return _trial_ap([s], method_half), f"{other} method half ({partners[0].config})"


def choose(scores: dict[str, list[float] | None]) -> str | None:
    """The method with the highest mean score over seeds (the first listed on a tie); None if none is scored."""
    means = {k: float(np.mean(v)) for k, v in scores.items() if v}
    return max(means, key=lambda k: (means[k], -list(means).index(k))) if means else None


def _trial_ap(scores: list[Scores], keep) -> float:
    """Mean over seeds of the AP on the markers of the trials `keep` (sequence indices)."""
    out = []
    for s in scores:
        rows = np.repeat(np.isin(s.sequence, list(keep)), len(s.probs) // len(s.sequence))
        out.append(float(average_precision_score(s.labels[rows], s.probs[rows])))
    return float(np.mean(out))


def crossfit_by_trials(per_method: dict[str, list[Scores]], n_folds: int = 2) -> dict:
    """Choose and score on one set: its trials in `n_folds` folds (by sorted sequence index, round robin); for each
    fold the method with the best mean AP on the *other* folds' trials is chosen and its scores of the fold are kept.
    -> {"choices": [method per fold], "folds": [trial lists], "scores": per seed (probs, labels) pooled over the
    folds}. Every method's seeds must score the same trials in the same order."""
    methods = list(per_method)
    first = per_method[methods[0]][0]
    trials = np.unique(first.sequence)
    if n_folds < 2 or len(trials) < n_folds:
        raise ValueError(f"cross-fitting needs 2 <= n_folds <= trials ({len(trials)}), got {n_folds}")
    if any(not np.array_equal(s.sequence, first.sequence) for v in per_method.values() for s in v):
        raise ValueError("cross-fitting: every method's runs must score the same trials in the same order")
    folds = [set(trials[i::n_folds].tolist()) for i in range(n_folds)]
    per_marker = len(first.probs) // len(first.sequence)
    choices, pooled = [], [([], []) for _ in per_method[methods[0]]]
    for fold in folds:
        rest = set(trials.tolist()) - fold
        best = choose({m: [_trial_ap(per_method[m], rest)] for m in methods})
        choices.append(best)
        for i, s in enumerate(per_method[best]):
            rows = np.repeat(np.isin(s.sequence, list(fold)), per_marker)
            pooled[i][0].append(s.probs[rows])
            pooled[i][1].append(s.labels[rows])
    return {"choices": choices, "folds": [sorted(f) for f in folds],
            "scores": [(np.concatenate(p), np.concatenate(lab)) for p, lab in pooled]}
