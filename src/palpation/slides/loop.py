"""The residual loop on measured slides (issue 12): per fold, add the candidate effect that lowers the
per-frame marker MAE on the fold's trials most, round by round, and score each round on the other fold.

An effect is a set of registry parameters (conf/slide_loop.yaml `effects`). A round searches every remaining
effect's parameters on the fitted trials and keeps the best effect if it lowers the fitted MAE by at least
`min_improvement_px`, then replays the kept twin on the held-out trials. Two searches (`search.sampler`):
* `tpe` (default): a continuous search within each parameter's physical bounds (palpation.twin.parameters,
  log-scaled where the registry says), one seeded Optuna TPE study per effect and round; `search.batches`
  sequential twin batches, each holding `search.per_batch` asks of every remaining effect (all effects of a
  batch in one twin call); the first batch tries the effect's first `per_batch` listed values (then random
  starts if it lists fewer), the later ones are TPE's;
* `grid`: the effects' value lists (value i of every list of one effect is candidate i), one twin batch.
Which effect and value are chosen uses the fitted trials only; the held-out trials and the labels only score.
The inner gate (`gate.inner`, slides.gate): the best `gate.tries` effects by fitted MAE are searched again
once per inner fold of the fitting fold's trials (leave one trial out), each fit scored on the trials it left
out; the best-ranked effect whose left-out trials improve significantly (paired test) is kept, else none.
"""

from __future__ import annotations

import logging
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import optuna

from palpation.measured_sequences import SequenceSet
from palpation.slides.fold_batches import run_folds_together
from palpation.slides.folds import other, trial_folds
from palpation.slides.gate import GateSettings, inner_splits, verdict
from palpation.slides.replay import SCENE_PARAMETERS, SCHEDULE_KEYS, frame_mae, frame_mae_abs, slide_modes, vessel_ratio
from palpation.twin.parameters import PARAMETERS

log = logging.getLogger(__name__)
# mae_*: marker motion about each trial's median (slides.replay.frame_mae); mae_abs_heldout_px: the absolute error
# at_bounds: the kept parameters at a physical bound ("; "-joined), a symptom (slide_loop.at_bounds)
# mae_inner_cv_px, gate_p: the inner gate's mean left-out MAE of the kept effect and its paired test's p (nan: off)
COLUMNS = ("fold", "round", "effect_added", "mae_fit_px", "mae_heldout_px", "vessel_ratio_sim", "vessel_ratio_real",
           "mae_abs_heldout_px", "at_bounds", "mae_inner_cv_px", "gate_p")
Evaluate = Callable[[SequenceSet, list[dict]], tuple[np.ndarray, np.ndarray]]  # -> markers (C,T,F,127,2), failed (C,T)
SAMPLERS = ("tpe", "grid")


def bounds_of(name: str):
    """The search range of a slide-loop parameter: the twin's registry, else the real scene's (slides.replay)."""
    return PARAMETERS.get(name) or SCENE_PARAMETERS[name]


@dataclass
class SearchSettings:
    sampler: str = "tpe"
    batches: int = 3  # sequential twin batches per round (tpe)
    per_batch: int = 3  # asks per effect and batch (tpe)
    seed: int = 0


@dataclass
class SlideLoopSettings:
    effects: dict[str, dict[str, list[float]]]
    base: dict[str, float] = field(default_factory=dict)
    max_rounds: int = 3
    min_improvement_px: float = 0.05
    search: SearchSettings = field(default_factory=SearchSettings)
    gate: GateSettings = field(default_factory=GateSettings)

    def validate(self, where: str = "conf/slide_loop.yaml") -> "SlideLoopSettings":
        known = {p.name for p in PARAMETERS.values() if p.per_env} | set(SCHEDULE_KEYS)
        for name in (*self.base, *(k for grid in self.effects.values() for k in grid)):
            if name not in known:
                raise ValueError(f"{where}: unknown parameter '{name}'; use one of {sorted(known)} "
                                 "(palpation.twin.parameters)")
        for effect, grid in self.effects.items():
            lengths = {len(v) for v in grid.values()}
            if len(lengths) != 1 or 0 in lengths:
                raise ValueError(f"{where}: effects.{effect} needs value lists of one common, non-zero length "
                                 f"(candidate i takes value i of each), got {({k: len(v) for k, v in grid.items()})}")
            for name, values in grid.items():
                p = bounds_of(name)
                if not p.low <= min(values) <= max(values) <= p.high:
                    raise ValueError(f"{where}: effects.{effect}.{name} = {list(values)} leaves its physical bounds "
                                     f"[{p.low:g}, {p.high:g}] {p.unit} ({p.why}; palpation/twin/parameters.py, "
                                     "slides/replay.py SCENE_PARAMETERS)")
        if self.max_rounds < 0 or self.min_improvement_px < 0:
            raise ValueError(f"{where}: need max_rounds >= 0 and min_improvement_px >= 0")
        s = self.search
        if s.sampler not in SAMPLERS or s.batches < 1 or s.per_batch < 1:
            raise ValueError(f"{where}: search.sampler must be one of {SAMPLERS} with search.batches >= 1 and "
                             f"search.per_batch >= 1, got {s}")
        self.gate.validate(where)
        return self


def candidates_of(grid: dict[str, list[float]]) -> list[dict]:
    names = list(grid)
    return [dict(zip(names, map(float, values))) for values in zip(*(grid[n] for n in names))]


def _score(evaluate: Evaluate, sset: SequenceSet, cands: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """Markers and the per-trial motion MAE (C, T) of every candidate."""
    markers, failed = evaluate(sset, cands)
    mae = frame_mae(np.nan_to_num(markers, nan=1e6), sset)
    mae[failed] = np.inf  # a diverged twin never wins
    return markers, mae


def at_bounds(params: dict, rel: float = 0.02) -> list[str]:
    """Parameters within `rel` of their search width (log width for log-scaled ones) of a registry bound: a
    symptom that the fit wants more than the physical range allows (docs/slides.md)."""
    out = []
    for name, value in params.items():
        p = PARAMETERS.get(name) or SCENE_PARAMETERS.get(name)
        if p is None or p.high <= p.low:
            continue
        lo, hi, x = (np.log(p.low), np.log(p.high), np.log(value)) if p.log and p.low > 0 and value > 0 else \
            (p.low, p.high, value)
        if min(x - lo, hi - x) <= rel * (hi - lo):
            out.append(f"{name}={value:g} at its {'lower' if x - lo <= hi - x else 'upper'} bound "
                       f"[{p.low:g}, {p.high:g}] {p.unit}")
    return out


def _round_grid(score, current: dict, remaining: list[str], settings: SlideLoopSettings):
    cands, owners = [], []
    for effect in remaining:
        for c in candidates_of(settings.effects[effect]):
            cands.append({**current, **c})
            owners.append(effect)
    return cands, owners, (score(cands) if cands else np.zeros((0, 0)))


def _round_tpe(score, current: dict, remaining: list[str], settings: SlideLoopSettings, seed: int):
    """Every remaining effect's parameters searched in [low, high] (registry), `batches` x `per_batch` asks."""
    s = settings.search
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    studies = {e: optuna.create_study(sampler=optuna.samplers.TPESampler(
        seed=seed + 7919 * i, n_startup_trials=s.per_batch, multivariate=True)) for i, e in enumerate(remaining)}
    for effect in remaining:  # the first batch starts from the effect's listed values, the rest is the sampler's
        for c in candidates_of(settings.effects[effect])[:s.per_batch]:
            studies[effect].enqueue_trial(c)
    cands, owners, maes = [], [], []
    for _ in range(s.batches):
        asked = []
        for effect in remaining:
            for _ in range(s.per_batch):
                trial = studies[effect].ask()
                c = {n: trial.suggest_float(n, bounds_of(n).low, bounds_of(n).high, log=bounds_of(n).log)
                     for n in settings.effects[effect]}
                asked.append((effect, trial))
                cands.append({**current, **c})
                owners.append(effect)
        mae = score(cands[-len(asked):])
        for (effect, trial), m in zip(asked, mae.mean(axis=1)):
            studies[effect].tell(trial, float(m) if np.isfinite(m) else 1e9)
        maes.append(mae)
    return cands, owners, np.concatenate(maes) if maes else np.zeros((0, 0))


def _inner_grid(mat: np.ndarray, owners: list[str], effects: list[str], splits) -> dict[str, np.ndarray]:
    """grid: per inner fold, the effect's value with the best MAE on the trials kept in, scored on those left out
    (every value was already replayed on every fitted trial: no twin call)."""
    out = {}
    for e in effects:
        rows = mat[[i for i, o in enumerate(owners) if o == e]]
        per = np.full(mat.shape[1], np.inf)
        for left in splits:
            per[left] = rows[int(np.argmin(np.delete(rows, left, axis=1).mean(axis=1)))][left]
        out[e] = per
    return out


def _inner_tpe(score, current: dict, effects: list[str], splits, settings: SlideLoopSettings,
               seed: int) -> dict[str, np.ndarray]:
    """tpe: every (effect, inner fold) searched as the round's search does (same batches, asks and first values,
    its own seeded study) on the trials kept in, all in `search.batches` twin calls; each candidate is replayed on
    every fitted trial so the left-out ones are scored by the best fit that did not see them."""
    s = settings.search
    studies = {}
    for i, e in enumerate(effects):
        for j in range(len(splits)):
            st = optuna.create_study(sampler=optuna.samplers.TPESampler(
                seed=seed + 7919 * i + 104729 * (j + 1), n_startup_trials=s.per_batch, multivariate=True))
            for c in candidates_of(settings.effects[e])[:s.per_batch]:
                st.enqueue_trial(c)
            studies[(e, j)] = st
    best = {key: (np.inf, None) for key in studies}
    for _ in range(s.batches):
        asked, cands = [], []
        for key, st in studies.items():
            for _ in range(s.per_batch):
                trial = st.ask()
                cands.append({**current, **{n: trial.suggest_float(n, bounds_of(n).low, bounds_of(n).high,
                                                                   log=bounds_of(n).log)
                                            for n in settings.effects[key[0]]}})
                asked.append((key, trial))
        for (key, trial), row in zip(asked, score(cands)):
            m = float(np.delete(row, splits[key[1]]).mean())
            studies[key].tell(trial, m if np.isfinite(m) else 1e9)
            if m < best[key][0]:
                best[key] = (m, row)
    out = {e: np.full(sum(map(len, splits)), np.inf) for e in effects}
    for (e, j), (_, row) in best.items():
        if row is not None:
            out[e][splits[j]] = row[splits[j]]
    return out


def run_fold(evaluate: Evaluate, fit: SequenceSet, held: SequenceSet, settings: SlideLoopSettings,
             fold: str) -> tuple[list[dict], list[dict], list[dict]]:
    """Rows of one fold (round 0 = the base twin), the parameters after each round and the inner gate's tries."""
    current = dict(settings.base)
    real_ratio = vessel_ratio(held.markers, held.labels)
    gate, nan = settings.gate, float("nan")

    def row(k: int, effect: str, mae_fit: float, v: dict | None) -> dict:
        m_held, mae_held = _score(evaluate, held, [current])
        r = {"fold": fold, "round": k, "effect_added": effect, "mae_fit_px": float(mae_fit),
             "mae_heldout_px": float(mae_held[0].mean()), "vessel_ratio_sim": vessel_ratio(m_held[0], held.labels),
             "vessel_ratio_real": real_ratio, "modes_heldout": slide_modes(m_held[0], held),
             "mae_abs_heldout_px": float(frame_mae_abs(m_held[0], held).mean()),
             "at_bounds": "; ".join(at_bounds({n: current[n] for n in searched})),
             "mae_inner_cv_px": v["mae_inner_cv_px"] if v else nan, "gate_p": v["p"] if v else nan}
        log.info("fold %s round %d (%s): motion MAE fit %.3f px, held-out %.3f px (absolute %.3f px), "
                 "vessel ratio sim %.3f / real %.3f%s", fold, k, effect, r["mae_fit_px"], r["mae_heldout_px"],
                 r["mae_abs_heldout_px"], r["vessel_ratio_sim"], real_ratio,
                 f"; SYMPTOM {r['at_bounds']}" if r["at_bounds"] else "")
        return r

    def score(cands: list[dict]) -> np.ndarray:
        return _score(evaluate, fit, cands)[1]

    now = score([current])[0]  # the current twin's per-trial fitted MAE: the gate's "before"
    searched: list[str] = []  # the kept effects' parameters (a base value switched off is no symptom)
    rows, params, tries = [row(0, "none", now.mean(), None)], [dict(current)], []
    remaining = list(settings.effects)
    splits = inner_splits(fit.n_trials, gate.inner_folds)
    for k in range(1, settings.max_rounds + 1):
        if not remaining:
            break
        # a fold's seed differs from the other's and every round's from the last
        seed = settings.search.seed + 1000 * k + (0 if fold == "odd" else 500)
        if settings.search.sampler == "grid":
            cands, owners, mat = _round_grid(score, current, remaining, settings)
        else:
            cands, owners, mat = _round_tpe(score, current, remaining, settings, seed)
        mae = mat.mean(axis=1)
        best_of: dict[str, int] = {}
        for i, o in enumerate(owners):
            if o not in best_of or mae[i] < mae[best_of[o]]:
                best_of[o] = i
        ranked = [e for e in sorted(best_of, key=lambda e: mae[best_of[e]])
                  if mae[best_of[e]] < rows[-1]["mae_fit_px"] - settings.min_improvement_px]
        if not ranked:
            best = int(np.argmin(mae))
            log.info("fold %s round %d: no effect lowers the fitted MAE by %.3f px (best %s %.3f); stop",
                     fold, k, settings.min_improvement_px, owners[best], mae[best])
            break
        kept, kept_v = ranked[0], None
        if gate.inner:  # the best `tries` effects, each fitted without every trial in turn (slides.gate)
            tried = ranked[:gate.tries]
            inner = (_inner_grid(mat, owners, tried, splits) if settings.search.sampler == "grid" else
                     _inner_tpe(score, current, tried, splits, settings, seed + 250)) if splits else {}
            kept = None
            for e in tried:
                # no inner fold (a fold of one trial): nothing can be left out, so nothing is shown and it is refused
                v = verdict(now, inner.get(e, np.full(len(now), np.nan)), gate, settings.min_improvement_px)
                tries.append({"fold": fold, "round": k, "effect": e, "mae_fit_px": float(mae[best_of[e]]), **v})
                log.info("fold %s round %d gate %s: fitted %.3f px; left-out trials %.3f -> %.3f px (%s test p %.3g,"
                         " alpha %g, %d trials): %s", fold, k, e, mae[best_of[e]], v["mae_before_px"],
                         v["mae_inner_cv_px"], gate.test, v["p"], gate.alpha, v["n_trials"],
                         "kept" if v["passed"] and kept is None else "passed" if v["passed"] else "refused")
                if v["passed"] and kept is None:
                    kept, kept_v = e, v
            if kept is None:
                log.info("fold %s round %d: the inner gate refuses %s (no left-out improvement beyond its noise); "
                         "stop", fold, k, tried)
                break
        i = best_of[kept]
        current, now = cands[i], mat[i]
        remaining.remove(kept)
        searched += list(settings.effects[kept])
        rows.append(row(k, kept, mae[i], kept_v))
        params.append(dict(current))
    return rows, params, tries


def _log_to_stderr(level: int) -> None:
    """A spawned fold worker has no logging set up (Hydra configured the parent only): its rounds and twin calls go to
    the stderr it shares with the parent, which the workflow's log captures."""
    logging.basicConfig(level=level, format="[%(asctime)s][%(name)s][%(levelname)s] - %(message)s")


def run_slide_loop(evaluate: Evaluate, sset: SequenceSet, settings: SlideLoopSettings, trial_numbers: list[int],
                   workers: int = 1, batch_folds: bool = False) -> dict:
    """Both folds: rows (COLUMNS), per-fold parameters per round, and the folds' trial numbers. The folds share
    nothing, so `workers` 2 runs them in two spawned processes (`evaluate` must then pickle: apps.slide_loop's
    Replayer) with the same result as one after the other (tests/slides/test_replay.py). `batch_folds`: the folds in
    threads whose twin calls run as one batch (slides.fold_batches; `evaluate.many` runs them)."""
    folds = trial_folds(trial_numbers)
    jobs = [(evaluate, sset.subset(idx), sset.subset(folds[other(fold)]), settings, fold) for fold, idx in folds.items()]
    if batch_folds:
        parts = run_folds_together(run_fold, jobs, evaluate.many)
    elif workers > 1:
        level = logging.getLogger().getEffectiveLevel()
        with ProcessPoolExecutor(min(workers, len(jobs)), mp_context=multiprocessing.get_context("spawn"),
                                 initializer=_log_to_stderr, initargs=(level,)) as pool:
            parts = list(pool.map(run_fold, *zip(*jobs)))
    else:
        parts = [run_fold(*job) for job in jobs]
    return {"rows": [r for rows, _, _ in parts for r in rows],
            "params": {fold: params for fold, (_, params, _) in zip(folds, parts)},
            "gate": [t for _, _, tries in parts for t in tries],
            "folds": {f: [trial_numbers[i] for i in idx] for f, idx in folds.items()}}
