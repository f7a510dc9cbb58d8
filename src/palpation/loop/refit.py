"""What re-fitting the parameters the twin already has can explain (issue 13: compensation).

A recalibration of 14 trials rarely converges, so a round leaves a residual that the *current* parameters
could still remove. The next round's candidate then soaks it up (a mount tilt taking what an incomplete
contact fit left), and the final check reads it as unexplained. Two guards, both on re-fitting alone:

* the **null try** (`null_problem`): in every round, next to the effect tries and in the same twin batches,
  the current parameter set is recalibrated with the same budget and warm starts of the same kind (the
  current values and Gauss-Newton steps on the refit columns) but without any new effect. An effect is
  kept only if it passes the gate against the null try as well as against the previous twin: its gain
  must go beyond what re-fitting buys with the same effort (engine.run_rounds);
* the **final refit** (`converge`): before the final check, Gauss-Newton iterations on the refit columns
  (step halving, a step kept only if the fitted MAE falls and the held-out is not significantly worse)
  bring the final twin to its optimum, so the residual tested against the detector noise is what the
  twin cannot reach, not what the search left.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Mapping

import numpy as np

from palpation.loop.attribution import Signature, fit_subset
from palpation.loop.effects import clip, move
from palpation.loop.gate import heldout_z

log = logging.getLogger(__name__)
NULL = "~null"  # suffix of a null try's problem name
STEP_FRACTIONS = (0.25, 0.5, 1.0)  # Gauss-Newton step halving (the signature is a secant at the nominal step)


def gauss_newton(p, residual: np.ndarray, refit: Signature, steps: Mapping[str, float],
                 limits: Mapping | None = None, fractions=STEP_FRACTIONS, min_rms_px: float = 0.02) -> list[dict]:
    """Parameter sets along the least-squares step of the refit columns (p.refit's dofs), clipped."""
    beta, _ = fit_subset(-np.asarray(residual).reshape(-1), [refit], min_rms_px)
    out = []
    for f in fractions:
        params = dict(p.params)
        for dof, b in zip(p.refit, beta):
            params = move(params, dof, f * float(b), steps)
        out.append(clip(params, limits))
    return out


def null_problem(p, searched: list[str], trust: Mapping, warm_residual: np.ndarray, refit: Signature,
                 steps: Mapping[str, float], limits: Mapping | None = None):
    """(a copy of problem p that re-fits `searched` with no new effect, its warm starts)."""
    q = replace(p, name=p.name + NULL, params=dict(p.params), searched=list(searched), trust=dict(trust),
                rounds=[], effects=list(p.effects), candidates=[])
    return q, [dict(p.params), *gauss_newton(p, warm_residual, refit, steps, limits)]


def fit_residual(p) -> np.ndarray:
    return np.stack([p.markers[i] - t.markers for i, t in enumerate(p.targets) if t.fit])


def converge(problems: list, simulate, signatures, steps: Mapping[str, float], limits: Mapping | None,
             iters: int, z_crit: float) -> dict[str, dict]:
    """Gauss-Newton iterations of every problem's refit dofs, all problems in one batch per iteration.

    `signatures(problems)` returns {name: refit Signature} at their current params. A step (best of the
    STEP_FRACTIONS) is kept only if the fitted MAE falls and the held-out change is not significantly
    worse (z >= -z_crit); a problem stops when no step helps. Returns per problem the fit/held-out MAE
    before and after and the iterations kept."""
    log_ = {p.name: {"before": p.summary(), "kept": 0} for p in problems}
    going = [p for p in problems if p.refit]
    for it in range(iters):
        if not going:
            break
        refits = signatures(going)
        jobs, spans = [], []
        for p in going:
            cands = gauss_newton(p, fit_residual(p), refits[p.name], steps, limits)
            spans.append((p, len(jobs), cands))
            jobs += [(t.state, c) for c in cands for t in p.targets]
        markers, failed = simulate(jobs)
        still = []
        for p, start, cands in spans:
            n, best = len(p.targets), None
            for j, c in enumerate(cands):
                block, bad = markers[start + j * n:start + (j + 1) * n], failed[start + j * n:start + (j + 1) * n]
                if bad.any() or not np.all(np.isfinite(block)):
                    continue
                s = p.summary(block)
                if s["fit"] < (best[1]["fit"] if best else p.summary()["fit"]):
                    best = (c, s, block)
            if best is None:
                continue
            held = [i for i, t in enumerate(p.targets) if not t.fit]
            z = heldout_z([p.targets[i].markers for i in held], [p.markers[i] for i in held],
                          [best[2][i] for i in held])["z"] if held else 0.0
            if z < -z_crit:
                continue  # the refit overfits the fitted states: stop here
            p.params, p.markers = dict(best[0]), best[2]
            log_[p.name]["kept"] += 1
            still.append(p)
        going = still
    for p in problems:
        log_[p.name]["after"] = p.summary()
        if log_[p.name]["kept"]:
            log.info("loop '%s': final refit, %d Gauss-Newton step(s): fit MAE %.3f -> %.3f px", p.name,
                     log_[p.name]["kept"], log_[p.name]["before"]["fit"], log_[p.name]["after"]["fit"])
    return log_
