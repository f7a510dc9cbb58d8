"""The slide loop's honest gate (issue 12; docs/slides.md, "Inner gate"): an effect is kept only if,
fitted without a trial of the fitting fold, it scores that trial better than the current twin, weighed against
the trial-to-trial noise by a one-sided paired test over the fold's trials.

Why: the loop's own acceptance saw only the fitted trials, and in the paper run both folds kept an effect that
made the other fold worse (odd: phantom_tilt, held-out 1.523 -> 1.960 px). The other fold stays the final judge
and never chooses; the gate uses only the fitting fold's trials, each scored by a fit that did not see it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

TESTS = ("t", "wilcoxon")


@dataclass
class GateSettings:
    inner: bool = False  # off: the earlier rule (the fitted MAE alone); conf/slide_loop.yaml turns it on
    inner_folds: int | None = None  # None: leave one trial out; K: K interleaved groups of the fold's trials
    test: str = "t"  # "t": one-sided paired t-test; "wilcoxon": one-sided signed-rank (exact for small n)
    alpha: float = 0.05
    tries: int = 1  # effects per round (best fitted MAE first) searched inner-fold in the same twin batches

    def validate(self, where: str = "conf/slide_loop.yaml") -> "GateSettings":
        if self.test not in TESTS or not 0 < self.alpha < 1 or self.tries < 1:
            raise ValueError(f"{where}: gate.test must be one of {TESTS}, 0 < gate.alpha < 1 and gate.tries >= 1, "
                             f"got {self}")
        if self.inner_folds is not None and self.inner_folds < 2:
            raise ValueError(f"{where}: gate.inner_folds = {self.inner_folds} must be >= 2 (null: one per trial)")
        return self


def inner_splits(n_trials: int, k: int | None) -> list[np.ndarray]:
    """Left-out trial indices of each inner fold: one per trial (k None), else k interleaved groups."""
    k = n_trials if k is None else min(int(k), n_trials)
    return [np.arange(i, n_trials, k) for i in range(k)] if n_trials >= 2 else []


def paired_p(before: np.ndarray, after: np.ndarray, test: str) -> float:
    """One-sided p that `after` is lower than `before` (paired per trial); 1 where no test is possible."""
    d = np.asarray(before, float) - np.asarray(after, float)
    if d.size < 2 or not np.all(np.isfinite(d)) or not np.any(d):
        return 1.0
    if test == "wilcoxon":
        return float(stats.wilcoxon(d, alternative="greater").pvalue)
    if np.ptp(d) == 0:  # t: every trial moved by the same amount, no spread to weigh it against
        return 0.0 if d[0] > 0 else 1.0
    return float(stats.ttest_1samp(d, 0.0, alternative="greater").pvalue)


def verdict(before: np.ndarray, inner: np.ndarray, gate: GateSettings, min_improvement_px: float) -> dict:
    """Per-trial MAE of the current twin and of the inner fits (each trial from the fit that left it out)."""
    before, inner = np.asarray(before, float), np.asarray(inner, float)
    p = paired_p(before, inner, gate.test)
    gain = float(np.mean(before - inner)) if before.size else float("nan")
    passed = bool(before.size >= 2 and np.all(np.isfinite(inner)) and gain >= min_improvement_px and p < gate.alpha)
    return {"mae_before_px": float(np.mean(before)) if before.size else float("nan"),
            "mae_inner_cv_px": float(np.mean(inner)) if inner.size else float("nan"), "gain_px": gain,
            "p": p, "test": gate.test, "alpha": gate.alpha, "n_trials": int(before.size), "passed": passed,
            "per_trial_before_px": before.tolist(), "per_trial_inner_px": inner.tolist()}
