"""Explain a residual by effect signatures: bounded least squares, BIC over subsets, a ranking.

The twin misses what the data show, so the change it needs is y = real - sim (= -residual), stacked
over the fitted states' markers. Each candidate effect contributes its signature columns (one per
dof: the marker-field change at the nominal step). For a subset S of effects,
    min ||y - X_S beta||^2  with beta >= 0 on the dofs that are physical only one way,
and BIC(S) = N ln(RSS_S / N) + k_S ln N (N = stacked coordinates, k_S = columns). Effects are ranked
by the share of the residual energy each explains alone; the one named is the best-ranked effect of
the BIC-best subset (none if that subset is empty: nothing explains the residual better than noise).

Given `nuisance` columns (the twin's own parameters, which the round re-fits with any new effect), every fit
holds them too and shares are of what they leave: an effect whose signature lies partly along E's column
(a stiffer shell) is credited with what it explains once E may move as well, as the round will let it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
from scipy.optimize import lsq_linear


@dataclass
class Signature:
    effect: str
    dofs: list[str]
    columns: np.ndarray  # (N, k) marker-field changes, stacked like y
    nonneg: list[bool]


@dataclass
class Attribution:
    named: str | None
    ranking: list[dict]  # per effect, best first: share, bic_delta, beta per dof
    best_subset: list[str]
    best_subset_share: float
    n_obs: int
    betas: dict[str, dict[str, float]] = field(default_factory=dict)  # effect -> dof -> beta (alone)

    def share_of(self, effect: str) -> float:
        return next((r["share"] for r in self.ranking if r["effect"] == effect), 0.0)


def fit_subset(y: np.ndarray, sigs: list[Signature], min_rms_px: float = 0.0) -> tuple[np.ndarray, float]:
    """Bounded least squares of y on the subset's columns: (beta, RSS).

    A column whose RMS change is below `min_rms_px` is dead (the effect cannot act on these states,
    e.g. a mount offset with nothing to touch): its beta stays 0 instead of blowing up on round-off.
    """
    if not sigs:
        return np.zeros(0), float(y @ y)
    X = np.concatenate([s.columns for s in sigs], axis=1)
    nonneg = np.concatenate([s.nonneg for s in sigs])
    rms = np.sqrt(np.mean(X ** 2, axis=0))
    live = rms > max(min_rms_px, 1e-12)
    beta = np.zeros(X.shape[1])
    if live.any():
        Xl, scale = X[:, live], np.linalg.norm(X[:, live], axis=0)
        lower = np.where(nonneg[live], 0.0, -np.inf)
        res = lsq_linear(Xl / scale, y, bounds=(lower, np.full(len(lower), np.inf)), method="bvls")
        beta[live] = res.x / scale
    r = y - X @ beta
    return beta, float(r @ r)


def bic(rss: float, n: int, k: int) -> float:
    return n * np.log(max(rss, 1e-300) / n) + k * np.log(n)


def attribute(residual: np.ndarray, signatures: list[Signature], max_subset: int | None = None,
              min_rms_px: float = 0.02, nuisance: Signature | None = None) -> Attribution:
    """Rank the effects by the residual share they explain and name the best one the BIC keeps.
    `nuisance`: columns held in every fit, the no-effect baseline included (module docstring)."""
    y = -np.asarray(residual, np.float64).reshape(-1)
    if not np.all(np.isfinite(y)):
        raise ValueError("attribution: the residual is not finite")
    for s in signatures:
        if s.columns.shape[0] != len(y) or not np.all(np.isfinite(s.columns)):
            raise ValueError(f"attribution: signature of '{s.effect}' has shape {s.columns.shape} or "
                             f"non-finite values; expected ({len(y)}, k) finite")
    held = [] if nuisance is None else [nuisance]
    k0 = 0 if nuisance is None else nuisance.columns.shape[1]
    n, rss0 = len(y), fit_subset(y, held, min_rms_px)[1]
    base_bic = bic(rss0, n, 0)
    ranking, betas = [], {}
    for s in signatures:
        beta, rss = fit_subset(y, [*held, s], min_rms_px)
        betas[s.effect] = dict(zip(s.dofs, map(float, beta[k0:])))
        ranking.append({"effect": s.effect, "share": 1.0 - rss / rss0 if rss0 > 0 else 0.0,
                        "bic_delta": bic(rss, n, s.columns.shape[1]) - base_bic, "beta": betas[s.effect]})
    ranking.sort(key=lambda r: -r["share"])
    best, best_bic, best_rss = [], base_bic, rss0
    top = len(signatures) if max_subset is None else max_subset
    for size in range(1, top + 1):
        for subset in combinations(signatures, size):
            _, rss = fit_subset(y, [*held, *subset], min_rms_px)
            value = bic(rss, n, sum(s.columns.shape[1] for s in subset))
            if value < best_bic:
                best, best_bic, best_rss = [s.effect for s in subset], value, rss
    named = next((r["effect"] for r in ranking if r["effect"] in best), None)
    return Attribution(named=named, ranking=ranking, best_subset=best,
                       best_subset_share=1.0 - best_rss / rss0 if rss0 > 0 else 0.0, n_obs=n, betas=betas)


def joint_candidates(residual: np.ndarray, signatures: list[Signature], conditional: dict[str, Signature],
                     requires: dict[str, tuple[str, ...]], pool: list[str], min_rms_px: float = 0.02,
                     nuisance: Signature | None = None) -> list[dict]:
    """Effect pairs to try jointly when single effects fail, best (lowest BIC) first.

    * dependent pairs: an effect that acts only through another (friction needs surface contact) is
      fitted with its `conditional` columns (its signature at the twin with the provider's nominal step on)
      next to the provider's own columns: alone its signature is dead;
    * independent pairs: any two live effects of `pool` (the BIC-best subset and the top of the ranking).
    A pair is kept only if its BIC beats no change and each of its members alone: two effects that only
    show together, or two that each explain part of the residual. `nuisance`: as in `attribute`."""
    y = -np.asarray(residual, np.float64).reshape(-1)
    n = len(y)
    held = [] if nuisance is None else [nuisance]
    by = {s.effect: s for s in signatures}
    alone = {e: bic(fit_subset(y, [*held, s], min_rms_px)[1], n, s.columns.shape[1]) for e, s in by.items()}
    plans = []
    for e, s in conditional.items():
        if all(r in by for r in requires.get(e, ())):
            plans.append(((*requires[e], e), [*(by[r] for r in requires[e]), s]))
    live = [e for e in dict.fromkeys(pool) if e in by and not requires.get(e)]
    plans += [((a, b), [by[a], by[b]]) for a, b in combinations(live, 2)]
    rss0 = fit_subset(y, held, min_rms_px)[1]
    out, base = [], bic(rss0, n, 0)
    for effects, sigs in plans:
        _, rss = fit_subset(y, [*held, *sigs], min_rms_px)
        value = bic(rss, n, sum(s.columns.shape[1] for s in sigs))
        if value < base and all(value < alone.get(e, base) for e in effects):
            out.append({"effects": tuple(effects), "bic": value, "share": 1.0 - rss / rss0 if rss0 > 0 else 0.0,
                        "sigs": sigs})
    return sorted(out, key=lambda d: d["bic"])
