"""Restarts: train a seed's model from several starts and keep the one the validation split prefers.

Start k of seed s trains exactly as seed s + STRIDE * k would (initial weights, the normalisation clips and
focal alpha of SPEC quirk 7, batch orders, dropout); start 0 is the seed's own run, so `train.restarts: 1`
changes nothing. The kept start is the one with the best `best_val_score` (the recipe's select_metric on the
training domain's validation split, first start on ties): no test set takes part. Why: with the reference
recipe a seed's 4-clip statistics draw decides much of its model (the quick profile's weak Sim seeds), and a
user who trains once should not get a weak draw when a better one is visible on val.
"""

from __future__ import annotations

import math
from dataclasses import replace

from palpation.model.train import FitResult, fit

STRIDE = 1000  # start k of seed s uses seed s + STRIDE * k: distinct from every other seed's starts below 1000


def start_seeds(seed: int, restarts: int) -> list[int]:
    if restarts < 1:
        raise ValueError(f"train.restarts={restarts}: use 1 (one start, the seed's own) or more")
    return [seed + STRIDE * k for k in range(restarts)]


def best_start(results: list[FitResult]) -> int:
    """Index of the start with the highest validation score; a NaN score never wins; the first on ties."""
    scores = [r.best_val_score if math.isfinite(r.best_val_score) else -math.inf for r in results]
    return scores.index(max(scores))


def keep_best(seed: int, results: list[FitResult]) -> tuple[FitResult, dict]:
    """The kept start's result (its steps, the starts' summed training seconds) and what metrics.json records."""
    k = best_start(results)
    kept = replace(results[k], train_seconds=sum(r.train_seconds for r in results))
    return kept, {"restarts": {"seeds": start_seeds(seed, len(results)), "chosen": k,
                               "val_scores": [float(r.best_val_score) for r in results]}}


def fit_restarts(train, val, rest, topo, model_cfg, cfg, seed: int, log_metrics=None,
                 progress: bool = False) -> tuple[FitResult, dict]:
    """`train.fit` from cfg.restarts starts; the kept start's (metrics, step) history is logged through
    `log_metrics` after the choice (one start: live, as `fit`). Returns the result and metrics.json's extra."""
    if cfg.restarts == 1:
        return fit(train, val, rest, topo, model_cfg, cfg, seed, log_metrics, progress=progress), {}
    results = []
    for s in start_seeds(seed, cfg.restarts):
        steps = []
        result = fit(train, val, rest, topo, model_cfg, cfg, s, lambda m, step, rec=steps: rec.append((dict(m), step)),
                     progress=progress)
        results.append(replace(result, steps=steps))
    kept, extra = keep_best(seed, results)
    for metrics, step in kept.steps if log_metrics else ():
        log_metrics(metrics, step)
    return kept, extra


def fit_seeds_restarts(train, val, rest, topo, model_cfg, cfg, seeds: list[int],
                       progress: bool = False) -> tuple[list[FitResult], dict[int, dict]]:
    """`stacked.fit_seeds` for every start of every seed trained together (seeds x restarts models in one
    stack); the kept start per seed, in `seeds` order, and each seed's metrics.json extra ({} for one start)."""
    from palpation.model.stacked import fit_seeds

    if cfg.restarts == 1:
        return fit_seeds(train, val, rest, topo, model_cfg, cfg, seeds, progress=progress), {s: {} for s in seeds}
    k = cfg.restarts
    flat = fit_seeds(train, val, rest, topo, model_cfg, cfg, [x for s in seeds for x in start_seeds(s, k)],
                     progress=progress)
    kept = [keep_best(s, flat[i * k:(i + 1) * k]) for i, s in enumerate(seeds)]
    return [r for r, _ in kept], {s: extra for s, (_, extra) in zip(seeds, kept)}
