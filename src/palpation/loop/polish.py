"""A local least-squares finish after a search: bounded Levenberg-Marquardt with a finite-difference
Jacobian whose columns are twin envs, every problem and start in one batch per step (issue 13).

A 14-trial Optuna study stops near an optimum, not at it. Comparing an effect's try with the null try (or
testing the final residual against the detector noise) at two unconverged points credits or blames an
effect for what the search left. So each try is finished by the same local solver before the gate:

* **parameters** are the problem's searched ones, each in its own unit: a log-scaled one in steps of
  FD_LOG in ln x (5 %), a linear one in steps of FD_LIN of its search width (2 %). The Jacobian is a
  forward difference of one unit (backward at an upper bound), so a column is the marker change per unit
  and the damping below is scale-free (Marquardt's diagonal). The loop's nominal steps (k_s 0 -> 2000,
  a 20 px principal point) are secants over a strongly nonlinear range and stalled the earlier
  Gauss-Newton refit (contact + camera: 1.35 -> 1.29 px, the camera off by 12 px); a small step is a
  derivative;
* **a step** solves min |J d + r|^2 + lam |D d|^2 (D^2 = diag(J'J)) for each lam in LAMBDAS (0 = the
  Gauss-Newton step, larger = shorter and closer to the gradient), clipped into the search bounds; all
  candidates of all chains are simulated in one batch and the best fitted MAE (the search's objective) is
  kept if it beats the current point, else the chain stops;
* **starts**: a chain per start (the search's best and, optionally, its next-best distinct trials: a
  camera recovered in the wrong basin is left there by any local step), the best chain wins.
Cost per iteration and chain: (1 + distinct physics columns) + len(LAMBDAS) envs per fitted state, in two
sequential twin batches (the camera and anchor columns share the base env).
"""

from __future__ import annotations

import logging
from typing import Mapping, Sequence

import numpy as np

from palpation.calibration.objective import marker_mae_px
from palpation.loop.effects import PARAMS, bounds

log = logging.getLogger(__name__)
FD_LOG = float(np.log(1.05))  # unit of a log-scaled parameter (in ln x)
FD_LIN = 0.02  # unit of a linear parameter, as a share of its search width
LAMBDAS = (0.0, 1.0, 10.0)  # Marquardt damping per candidate step
MIN_GAIN = 1e-3  # a step must lower the fitted MAE by this share, else the chain has converged


def units(names: Sequence[str], params: Mapping[str, float], limits: Mapping | None) -> dict[str, tuple]:
    """Per parameter polished: (log?, unit, low, high); a log parameter at <= 0 (switched off) is left out."""
    out = {}
    for n in names:
        low, high = bounds(n, limits)
        if PARAMS[n].log:
            if params[n] > 0 and low > 0:
                out[n] = (True, FD_LOG, low, high)
        else:
            out[n] = (False, FD_LIN * (high - low), low, high)
    return out


def shifted(params: Mapping[str, float], u: Mapping[str, tuple], d: Mapping[str, float]) -> dict[str, float]:
    """`params` moved by d[n] units of each parameter, clipped into its bounds."""
    out = dict(params)
    for n, step in d.items():
        log_, h, low, high = u[n]
        x = out[n] * np.exp(step * h) if log_ else out[n] + step * h
        out[n] = float(np.clip(x, low, high))
    return out


def lm_steps(J: np.ndarray, r: np.ndarray, lambdas=LAMBDAS) -> list[np.ndarray]:
    """Damped least-squares steps d (one per lambda) of min |J d + r|^2 + lam |D d|^2; dead columns get 0."""
    norms = np.linalg.norm(J, axis=0)
    live = norms > 1e-9 * max(float(norms.max(initial=0.0)), 1e-30)
    out = []
    for lam in lambdas:
        d = np.zeros(J.shape[1])
        if live.any():
            Jl = J[:, live]
            A = np.vstack([Jl, np.sqrt(lam) * np.diag(norms[live])]) if lam > 0 else Jl
            b = np.concatenate([-r, np.zeros(int(live.sum()))]) if lam > 0 else -r
            d[live] = np.linalg.lstsq(A, b, rcond=None)[0]
        out.append(d)
    return out


def distinct_starts(trials: Sequence[Mapping[str, float]], names: Sequence[str], limits: Mapping | None,
                    k: int, min_dist: float = 0.05) -> list[dict]:
    """Up to k of `trials` (best first) at least `min_dist` apart in the unit box of their search bounds."""
    def box(t):
        z = []
        for n in names:
            low, high = bounds(n, limits)
            if PARAMS[n].log and low > 0:
                z.append((np.log(max(t[n], low)) - np.log(low)) / (np.log(high) - np.log(low)))
            else:
                z.append((t[n] - low) / (high - low))
        return np.asarray(z)
    out, seen = [], []
    for t in trials:
        z = box(t)
        if all(np.max(np.abs(z - s)) >= min_dist for s in seen):
            out.append(dict(t))
            seen.append(z)
        if len(out) >= k:
            break
    return out


def _fits_above(x: float, unit: tuple) -> bool:
    log_, h, _, high = unit
    return (x * np.exp(h) if log_ else x + h) <= high


def _fit_mae(targets, block) -> float:
    return float(np.mean([marker_mae_px(m, t.markers) for t, m in zip(targets, block)]))


def polish(problems: list, starts: Mapping[str, Sequence[Mapping[str, float]]], simulate,
           limits: Mapping[str, Mapping | None], iters: int | Mapping[str, int]) -> dict[str, dict]:
    """Levenberg-Marquardt chains from every start of every problem, in lockstep (two twin batches per
    iteration over all chains). Sets each problem's params to its best chain's end point (p.markers are
    left for the caller to re-simulate on every state) and returns per problem the fitted MAE at the best
    start and at the end, the iterations kept, whether the best chain converged (False: stopped at `iters`
    while still descending) and the twin jobs of all chains together. The parameters
    polished are p.searched, within limits[p.name] (loop.search.bounds and the problem's trust region).
    `iters`: the iteration cap, one for all or per problem name (a problem's chains stop at its own)."""
    chains = []
    for p in problems:
        fit = [t for t in p.targets if t.fit]
        for s in starts.get(p.name, [p.params]):
            x = {**p.params, **dict(s)}
            chains.append({"p": p, "fit": fit, "x": x, "base": None, "mae": np.inf, "kept": 0, "going": True,
                           "converged": False, "cap": iters[p.name] if isinstance(iters, Mapping) else iters,
                           "u": units(p.searched, x, limits.get(p.name))})
    jobs_asked = 0
    for it in range(max((c["cap"] for c in chains), default=0) + 1):
        live = [c for c in chains if c["going"]]
        if not live:
            break
        jobs, spans = [], []  # batch 1: the base (first time) and one column per unit
        for c in live:
            sets = ([] if c["base"] is not None else [("base", c["x"])])
            if it < c["cap"]:
                for n in c["u"]:
                    sign = 1.0 if _fits_above(c["x"][n], c["u"][n]) else -1.0  # backward at an upper bound
                    sets.append((n, shifted(c["x"], c["u"], {n: sign}), sign))
            spans.append((c, len(jobs), sets))
            jobs += [(t.state, s[1]) for s in sets for t in c["fit"]]
        markers, failed = simulate(jobs) if jobs else (None, None)
        jobs_asked += len(jobs)
        for c, start, sets in spans:
            m = len(c["fit"])
            blocks = {}
            for j, s in enumerate(sets):
                b, bad = markers[start + j * m:start + (j + 1) * m], failed[start + j * m:start + (j + 1) * m]
                blocks[s[0]] = None if bad.any() or not np.all(np.isfinite(b)) else (b, s)
            if c["base"] is None:
                if blocks["base"] is None:
                    c["going"] = False  # the start itself diverged
                    continue
                c["base"], c["mae"] = blocks["base"][0], _fit_mae(c["fit"], blocks["base"][0])
                c["mae0"] = c["mae"]
            if it == c["cap"]:
                c["going"] = False
                continue
            cols = [n for n in c["u"] if blocks.get(n) is not None]
            r = np.concatenate([(c["base"][i] - t.markers).reshape(-1) for i, t in enumerate(c["fit"])])
            J = np.stack([(blocks[n][0] - c["base"]).reshape(-1) / blocks[n][1][2] for n in cols], axis=1) \
                if cols else np.zeros((r.size, 0))
            c["cands"] = [shifted(c["x"], c["u"], dict(zip(cols, d))) for d in lm_steps(J, r)]
        live = [c for c in live if c["going"]]
        if not live:
            break
        jobs, spans = [], []  # batch 2: the damped steps
        for c in live:
            spans.append((c, len(jobs)))
            jobs += [(t.state, x) for x in c["cands"] for t in c["fit"]]
        markers, failed = simulate(jobs)
        jobs_asked += len(jobs)
        for c, start in spans:
            m, best = len(c["fit"]), None
            for j, x in enumerate(c["cands"]):
                b, bad = markers[start + j * m:start + (j + 1) * m], failed[start + j * m:start + (j + 1) * m]
                if bad.any() or not np.all(np.isfinite(b)):
                    continue
                v = _fit_mae(c["fit"], b)
                if best is None or v < best[0]:
                    best = (v, x, b)
            if best is None or best[0] >= c["mae"] * (1.0 - MIN_GAIN):
                c["going"], c["converged"] = False, True  # converged (or every step diverged)
                continue
            c["mae"], c["x"], c["base"] = best[0], best[1], best[2]
            c["kept"] += 1
    out = {}
    for p in problems:
        mine = [c for c in chains if c["p"] is p and c["base"] is not None]
        if not mine:
            out[p.name] = {"kept": 0, "chains": 0, "jobs_all": jobs_asked, "converged": False}
            continue
        best = min(mine, key=lambda c: c["mae"])
        p.params = dict(best["x"])
        out[p.name] = {"fit_start": float(min(c["mae0"] for c in mine)), "fit_end": float(best["mae"]),
                       "kept": int(best["kept"]), "chains": len(mine), "jobs_all": jobs_asked,
                       "converged": bool(best["converged"])}
    return out
