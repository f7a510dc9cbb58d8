"""The loop: residual -> signatures -> attribution -> add the best effect -> recalibrate -> repeat.

Many problems (measured sets) advance in lockstep so that every twin call is one batch over all of
them: the real photos are one problem, the self-test has one per injected set. Per round and
problem: simulate the current twin at every state; compute each candidate's signature at the fitted
states; name the effect the attribution ranks best; recalibrate the searched parameters plus the new
effect's, warm-started at the attribution's linear estimate; keep the effect only if the held-out
MAE falls by at least min(min_improvement_px, min_improvement_rel x MAE) (the fitted MAE where nothing
is held out). A rejected effect restores the previous twin; the next-ranked one gets a try
(`tries_per_round`), and a round with no kept effect ends that problem's loop. An effect must also pass
the gate against the round's null try, the current parameters re-fitted with the same budget and no new
effect (loop.refit), so it is not credited with what finishing the old fit would have bought.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Mapping

import numpy as np

from palpation.loop.attribution import Signature, attribute, fit_subset, joint_candidates
from palpation.loop.compete import Winner, enter
from palpation.loop.config import LoopConfig
from palpation.loop.effects import EFFECTS, PARAMS, Dof, bounds, clip, move
from palpation.loop.gate import beyond_null, decide, heldout_z
from palpation.loop.problem import Problem, evaluate
from palpation.loop.projected import recheck
from palpation.loop.recalibrate import recalibrate
from palpation.loop.refit import NULL, finish, null_problem, subset_starts
from palpation.progress import bar

log = logging.getLogger(__name__)
# warm starts along the attribution's estimate: the signature is a secant at the nominal step, so a
# strongly nonlinear effect (damping: x33 needed, the secant at x5 says x500) overshoots. Two kinds:
# the new effect alone (the rest as is) and jointly with the current parameters (a Gauss-Newton step;
# adding surface contact moves E x3 on the photos). Either can be the better start, so both are tried.
WARM_FRACTIONS = (0.25, 0.5, 1.0)
JOINT_FRACTIONS = (0.5, 1.0)
REFIT = "_refit"  # signature of the parameters the twin already has
COND = "_cond:"  # prefix: a dependent effect's columns at the twin with its provider on
MIN_RMS_PX = 0.02  # a signature column below this RMS change is dead (attribution.fit_subset)


def refit_dofs(p: Problem) -> list[Dof]:
    """Dofs of what the twin already has: E (x 1.25) and every added effect's dofs, both signs allowed.

    Their columns turn the attribution into a Gauss-Newton step for all searched parameters at once,
    the recalibration's warm start (adding surface contact moves E x 3 on the photos)."""
    owned = {n for e in p.effects for n in EFFECTS[e].params}
    dofs = []
    for n in p.searched:
        if n not in owned:
            width = PARAMS[n].high - PARAMS[n].low
            dofs.append(Dof(n, ((n, "mul", 1.25),) if PARAMS[n].log else ((n, "add", 0.1 * width),), False))
    return dofs + [Dof(f"{e}.{d.name}", d.moves, False) for e in p.effects for d in EFFECTS[e].dofs]


def signatures(problems: list[Problem], simulate, steps: Mapping[str, float]
               ) -> tuple[dict[str, list[Signature]], dict[str, Signature], dict[str, dict[str, Signature]]]:
    """Per problem, each candidate's dof columns at the fitted states, the columns of the parameters it
    already has (REFIT, for the warm start) and, for a candidate that acts only through another candidate
    (EFFECTS[e].requires, e.g. friction through surface contact), its conditional columns at the twin with
    the provider's nominal step on (its own are dead there): one batch over all problems."""
    jobs, index, bases = [], [], {}
    for p in problems:
        fit = p.fit_targets()
        groups = [(e, EFFECTS[e].dofs, None) for e in p.candidates] + [(REFIT, p.refit, None)]
        for e in p.candidates:
            req = EFFECTS[e].requires
            if req and all(r in p.candidates for r in req):
                base = dict(p.params)
                for r in req:
                    for d in EFFECTS[r].dofs:
                        base = move(base, d, 1.0, steps)
                bases[(p.name, e)] = len(jobs)
                jobs += [(t.state, base) for t in fit]
                groups.append((COND + e, EFFECTS[e].dofs, base))
        for e, dofs, base in groups:
            for dof in dofs:
                index.append((p, e, dof, len(jobs)))
                jobs += [(t.state, move(p.params if base is None else base, dof, 1.0, steps)) for t in fit]
    markers, failed = simulate(jobs)
    out: dict[str, list[Signature]] = {p.name: [] for p in problems}
    cond: dict[str, dict[str, Signature]] = {p.name: {} for p in problems}
    cols: dict[tuple, list] = {}
    for p, e, dof, start in index:
        fit_ix = [i for i, t in enumerate(p.targets) if t.fit]
        ref = p.markers[fit_ix]
        if e.startswith(COND):
            b = bases[(p.name, e[len(COND):])]
            ref = p.markers[fit_ix] if failed[b:b + len(fit_ix)].any() else markers[b:b + len(fit_ix)]
        block = markers[start:start + len(fit_ix)]
        if failed[start:start + len(fit_ix)].any():
            log.warning("loop '%s': %s.%s diverged at its nominal step; its column is left out", p.name, e,
                        dof.name)
            block = ref
        cols.setdefault((p.name, e), []).append(((block - ref).reshape(-1), dof))
    refit = {}
    for p in problems:
        n = sum(t.fit for t in p.targets) * len(p.targets[0].markers) * 2
        for e in [*p.candidates, REFIT, *(COND + c for c in p.candidates)]:
            if e.startswith(COND) and (p.name, e) not in cols:
                continue
            c = cols.get((p.name, e), [])
            X = np.stack([x for x, _ in c], axis=1) if c else np.zeros((n, 0))
            name = e[len(COND):] if e.startswith(COND) else e
            sig = Signature(name, [d.name for _, d in c], X, [d.nonneg for _, d in c])
            if e == REFIT:
                refit[p.name] = sig
            elif e.startswith(COND):
                cond[p.name][name] = sig
            else:
                out[p.name].append(sig)
    return out, refit, cond


def linear_estimate(p: Problem, combo: tuple[str, ...], residual: np.ndarray, sigs: list[Signature],
                    refit: Signature, steps: Mapping[str, float], limits: Mapping | None = None) -> list[dict]:
    """Warm starts: the least-squares step of the new effects' dofs alone (WARM_FRACTIONS of it) and
    jointly with the current parameters' (p.refit, as at signature time; JOINT_FRACTIONS), clipped.
    `sigs`: the combo's columns in order (a dependent effect's conditional ones after its provider's)."""
    y = -np.asarray(residual).reshape(-1)
    alone, _ = fit_subset(y, sigs, MIN_RMS_PX)
    joint, _ = fit_subset(y, [refit, *sigs], MIN_RMS_PX)
    new = [d for e in combo for d in EFFECTS[e].dofs]
    plans = [(new, alone, WARM_FRACTIONS), ([*p.refit, *new], joint, JOINT_FRACTIONS)]
    out = []
    for dofs, beta, fractions in plans:
        for f in fractions:
            params = dict(p.params)
            for dof, b in zip(dofs, beta):
                params = move(params, dof, f * float(b), steps)
            out.append(clip(params, limits))
    return out


def trust_region(p: Problem, names, factor: float, overrides: Mapping | None = None) -> dict:
    """Log-scaled parameters already fitted: search within `factor` of their value (inside the bounds)."""
    if factor <= 1.0:
        return {}
    out = {}
    for n in names:
        if PARAMS[n].log and p.params[n] > 0:
            low, high = bounds(n, overrides)
            out[n] = (max(low, min(p.params[n] / factor, high)), min(high, max(p.params[n] * factor, low)))
    return out


def round_plan(p: Problem, att, sigs: list[Signature], cond: dict[str, Signature], residual: np.ndarray,
               cfg: LoopConfig, given: Signature | None = None) -> list[dict]:
    """What to try this round, in order: single effects of the BIC-best subset by rank
    (cfg.method.tries_per_round), then pairs tried jointly (cfg.method.pair_tries): dependent pairs and pairs of the
    BIC-best subset / top of the ranking (attribution.joint_candidates). Pairs are tried only after every
    single try failed the gate. `given`: columns held in every attribution fit (method.attribute_given_refit)."""
    by = {s.effect: s for s in sigs}
    singles = [r["effect"] for r in att.ranking if r["effect"] in att.best_subset][:cfg.method.tries_per_round]
    plan = [{"effects": (e,), "sigs": [by[e]], "share": att.share_of(e)} for e in singles]
    if cfg.method.pair_tries > 0:
        pool = [*att.best_subset, *[r["effect"] for r in att.ranking[:3]]]
        requires = {e: EFFECTS[e].requires for e in p.candidates}
        pairs = joint_candidates(residual, sigs, cond, requires, pool, MIN_RMS_PX, given)
        plan += [{"effects": d["effects"], "sigs": d["sigs"], "share": d["share"], "pair": True}
                 for d in pairs[:cfg.method.pair_tries]]
    return plan


def run_rounds(problems: list[Problem], simulate, cfg: LoopConfig, db_path: Path, twin_key: str,
               max_rounds: int, on_round=None, progress: bool = False) -> None:
    """Advance every problem until its loop stops; each attempt's record lands in problem.rounds.

    Within a round the plan (round_plan) is tried in order: the first effect set whose recalibrated twin
    passes the gate (loop.gate) is kept; if none does, the loop stops.
    `progress`: a tqdm bar over the rounds, and one per recalibration over its trials.
    """
    steps = dict(cfg.method.steps)
    rounds = bar(range(1, max_rounds + 1), desc="loop rounds", unit="round", enabled=progress)
    for k in rounds:
        active = [p for p in problems if not p.done and p.candidates]
        if not active:
            break  # every loop has stopped (the bar ends short of max_rounds)
        evaluate([p for p in active if p.markers is None], simulate)  # else still current from last round
        for p in active:
            p.refit = refit_dofs(p)
        sigs, refits, conds = signatures(active, simulate, steps)
        before, queue = {}, {}
        for p in active:
            p.last_signatures = {"params": dict(p.params), "sigs": sigs[p.name], "refit": refits[p.name],
                                 "cond": conds[p.name], "refit_dofs": list(p.refit)}
            fit_ix = [i for i, t in enumerate(p.targets) if t.fit]
            residual = np.stack([p.markers[i] - p.targets[i].markers for i in fit_ix])
            given = refits[p.name] if cfg.method.attribute_given_refit else None
            att = attribute(residual, sigs[p.name], min_rms_px=MIN_RMS_PX, nuisance=given)
            before[p.name] = (p.summary(), dict(p.params), p.markers.copy(), att, list(p.searched), residual)
            queue[p.name] = round_plan(p, att, sigs[p.name], conds[p.name], residual, cfg, given)
            if not queue[p.name]:
                p.done = True
                p.rounds.append(_record(k, p, None, att, before[p.name], None, accepted=False))
                log.info("loop '%s' round %d: no effect explains the residual (BIC); stop", p.name, k)
        nulls: dict[str, tuple] = {}  # per problem: the null try's (summary, markers, fit), or None if it diverged
        winners: dict[str, Winner] = {}  # per problem: the round's best set so far (loop.compete)
        ends: dict[str, list] = {p.name: [] for p in active}  # (effects, end params) of this round's tries
        for attempt in range(max((len(q) for q in queue.values()), default=0)):
            trying = [p for p in active if not p.done and len(queue[p.name]) > attempt]
            if not trying:
                break
            warm, extra = {}, []
            if attempt == 0 and cfg.method.null_try:  # re-fit without a new effect, in the same twin batches
                for p in [p for p in trying if before[p.name][4]]:  # something to re-fit
                    q, starts = null_problem(p, before[p.name][4], trust_region(p, before[p.name][4],
                                             cfg.search.trust_factor, cfg.search.bounds), before[p.name][5],
                                             refits[p.name], steps, cfg.search.bounds)
                    extra.append(q)
                    warm[q.name] = starts
            for p in trying:
                item, att = queue[p.name][attempt], before[p.name][3]
                old = before[p.name][4]
                p.searched = old + [n for e in item["effects"] for n in EFFECTS[e].params if n not in old]
                p.trust = trust_region(p, old, cfg.search.trust_factor, cfg.search.bounds)
                estimates = linear_estimate(p, item["effects"], before[p.name][5], item["sigs"], refits[p.name],
                                            steps, cfg.search.bounds)
                nested = subset_starts(ends[p.name], item["effects"]) if cfg.method.nested_starts else []
                warm[p.name] = [dict(before[p.name][1]), *nested, *estimates]  # nested: loop.refit
            fits = recalibrate([*trying, *extra], simulate, cfg.search, db_path, f"r{k}t{attempt}", twin_key, warm,
                               progress=progress)
            for p in [*trying, *extra]:
                p.params.update(fits[p.name]["params"])
            # every try (null too) at its local optimum; a try that adds the camera also from its best other basin
            finish(cfg, [*trying, *extra], fits, simulate,
                   {p.name for p in trying if "camera" in queue[p.name][attempt]["effects"]},
                   {q.name for q in extra} if cfg.method.null_converge else (), {q.name for q in extra})
            diverged = evaluate([*trying, *extra], simulate, strict=False)
            for q in extra:  # a diverged null try leaves the previous twin as the only reference
                nulls[q.name[:-len(NULL)]] = None if q.name in diverged else (q.summary(), q.markers, fits[q.name])
                if q.name not in diverged:
                    ends[q.name[:-len(NULL)]].append((frozenset(), fits[q.name]["params_final"]))
            for p in [p for p in trying if p.name not in diverged]:  # a start of the larger sets tried next
                ends[p.name].append((frozenset(queue[p.name][attempt]["effects"]), fits[p.name]["params_final"]))
            for p in trying:
                item, (b, b_params, b_markers, att, b_searched, _) = queue[p.name][attempt], before[p.name]
                if p.name in diverged:  # the fit's optimum was found on the fitted states only
                    why = f"the recalibrated twin diverged at {diverged[p.name]}"
                    nan = float("nan")
                    failed = {"fit": nan, "heldout": nan, "all": nan, "fit_result": fits[p.name], "gate": {"why": why}}
                    p.rounds.append(_record(k, p, item, att, before[p.name], failed, False))
                    log.info("loop '%s' round %d try %d: %s: %s; rejected", p.name, k, attempt + 1,
                             "+".join(item["effects"]), why)
                    p.params, p.markers, p.searched = dict(b_params), b_markers, list(b_searched)
                    continue
                a = p.summary()
                held = [i for i, t in enumerate(p.targets) if not t.fit]
                evidence = heldout_z([p.targets[i].markers for i in held], [b_markers[i] for i in held],
                                     [p.markers[i] for i in held])
                ok, why = decide(b, a, evidence, cfg.method.min_improvement_px, cfg.method.min_improvement_rel, cfg.method.gate_fit_rel,
                                 cfg.method.gate_z)
                after = {**a, "fit_result": fits[p.name], "gate": {**evidence, "why": why}}
                if nulls.get(p.name) is not None:  # and beyond what re-fitting alone reached (refit.py)
                    n_sum, n_markers, n_fit = nulls[p.name]
                    ev0 = heldout_z([p.targets[i].markers for i in held], [n_markers[i] for i in held],
                                    [p.markers[i] for i in held])
                    ok0, why0 = beyond_null(n_sum, a, ev0, cfg.method)
                    after["gate_null"] = {**ev0, "why": why0, "fit": n_sum["fit"], "heldout": n_sum["heldout"],
                                          "params": n_fit["params_final"],
                                          "converged": n_fit.get("polish", {}).get("converged")}
                    if ok and not ok0:
                        why = f"{why}; but not beyond re-fitting alone (null try: {why0})"
                    ok = ok and ok0
                    after["gate"]["why"] = why
                rec = _record(k, p, item, att, before[p.name], after, ok)
                rec["passed"] = ok  # the gate's own verdict; `accepted`: kept after the round's competition
                p.rounds.append(rec)
                if ok:
                    ok = enter(cfg, p, queue, attempt, winners, item, rec, a, fits[p.name]["starts"])
                log.info("loop '%s' round %d try %d: %s explains %.1f %% of the residual; MAE fit %.2f -> %.2f "
                         "px; %s: %s", p.name, k, attempt + 1, "+".join(item["effects"]), 100 * item["share"],
                         b["fit"], a["fit"], rec["after"]["gate"]["why"], "kept" if ok else "rejected")
                # the next try starts from the round's twin; the winner is applied when the round ends
                p.params, p.markers, p.searched = dict(b_params), b_markers, list(b_searched)
        proj = recheck(cfg, active, winners, before, simulate) if cfg.method.projected_null and cfg.method.null_try else {}
        for name, r in proj.items():  # the winner against its projected null (loop.projected)
            w = winners[name]
            w.record["after"]["gate_projected"] = r
            if not r["ok"]:
                w.record["accepted"] = w.record["passed"] = False
                w.record["after"]["gate"]["why"] += f"; but not beyond re-fitting alone (projected null: {r['why']})"
                del winners[name]
        for name, w in winners.items():
            p = next(q for q in active if q.name == name)
            p.params, p.markers, p.searched, p.starts = dict(w.params), w.markers, list(w.searched), w.starts
            for e in w.effects:
                p.effects.append(e)
                p.candidates.remove(e)
        for p in active:
            if not p.done and not any(r["round"] == k and r["accepted"] for r in p.rounds):
                p.done = True  # every try of this round was rejected
                if nulls.get(p.name) is not None and cfg.method.final_refit_starts > 1:  # the same set re-fitted: a
                    p.starts = [nulls[p.name][2]["params_final"], *p.starts][:cfg.method.final_refit_starts - 1]  # start
                if "params" in proj.get(p.name, {}) and cfg.method.final_refit_starts > 1:  # the projected null's end
                    p.starts = [proj[p.name]["params"], *p.starts][:cfg.method.final_refit_starts - 1]
        if on_round is not None:
            on_round(k, problems)
        rounds.set_postfix_str(f"{sum(not p.done for p in problems)} of {len(problems)} going", refresh=False)
    rounds.close()


def _record(k: int, p: Problem, item, att, before, after, accepted: bool) -> dict:
    b_summary, b_params, b_markers = before[:3]
    effects = list(item["effects"]) if item else []
    return {"round": k, "effect": "+".join(effects) or None, "effects": effects, "accepted": accepted,
            "share_explained": item["share"] if item else 0.0,
            "ranking": att.ranking, "best_subset": att.best_subset, "best_subset_share": att.best_subset_share,
            "before": b_summary, "params_before": b_params, "markers_before": b_markers, "after": after,
            "params_after": dict(p.params) if after else None,
            "markers_after": p.markers.copy() if after else None}
