"""The projected null (`loop.method.projected_null`, issue 13: self-test runs 28 and 48).

The round's null try re-fits the current set from the round's starting twin. When that twin sits in a
stall (the previous round's set ended above the noise and its LM chain cannot leave that point), the null
stays there even when converged, while a try that adds an effect starts elsewhere (its own warm starts,
the camera grid) and reaches the old set's true optimum *with the new effect nearly idle*. It then passes
the gate against the stalled null, and the extra effect is credited with what the old set could reach
(60-run H200 self-test, seed 0: run 48, viscous + anchoring at 2.19 px held-out, the converged null 1.43 px,
+ camera 0.39 px with alpha and the anchor recovered to 5 digits; run 28, contact + friction 0.41 px, +
viscous 0.29 px with k_s and mu at the truth).

The check: the round's winner is projected onto the old set (its new effects' parameters back at the
round's starting values, i.e. off) and that point is re-fitted without the new effects by Levenberg-Marquardt
to final_refit_iters steps; the winner is finished to the same cap, so both are compared at their optima
(the budget fairness of loop.method.null_converge). The winner is kept only if it passes the gate (loop.gate.decide)
against the projected null as it did against the null try. A nested set contains its subset's optimum
(loop.refit.subset_starts); this is the converse: a subset's fit must have seen the superset's end point.
"""

from __future__ import annotations

import logging
from dataclasses import replace

from palpation.loop.effects import EFFECTS
from palpation.loop.gate import beyond_null, heldout_z
from palpation.loop.polish import polish
from palpation.loop.problem import evaluate
from palpation.loop.refit import refit_kept

log = logging.getLogger(__name__)
PROJ = "~proj"  # suffix of a projected null's problem name
WIN = "~win"  # suffix of the winner's finish


def projected(winner_params: dict, start_params: dict, effects) -> dict:
    """The winner's parameters with its new effects' parameters back at the round's starting values (off)."""
    out = dict(winner_params)
    for e in effects:
        for n in EFFECTS[e].params:
            out[n] = start_params[n]
    return out


def recheck(cfg, problems: list, winners: dict, before: dict, simulate) -> dict[str, dict]:
    """Per problem with a winner and something to re-fit: finish the winner and its projected null to
    final_refit_iters LM steps (one batch per step for all), update the winner's params/markers/summary to
    its finished point when the fit falls and the held-out is not significantly worse, and gate the winner
    against the projected null. Returns {name: {"ok", "why", "fit", "heldout", "params", "converged"}}.
    `before[name]`: the engine's (summary, params, markers, attribution, searched, residual) of the round."""
    pairs = []
    for p in problems:
        w = winners.get(p.name)
        if w is None or not before[p.name][4]:
            continue
        start, searched = before[p.name][1], before[p.name][4]
        q = replace(p, name=p.name + PROJ, params=projected(w.params, start, w.effects), searched=list(searched),
                    rounds=[], candidates=[], markers=None)
        v = replace(p, name=p.name + WIN, params=dict(w.params), searched=list(w.searched), rounds=[],
                    candidates=[], markers=w.markers)
        pairs.append((p, w, q, v))
    if not pairs:
        return {}
    iters = max(cfg.method.polish_iters, cfg.method.final_refit_iters)
    probs = [x for _, _, q, v in pairs for x in (q, v)]
    limits = {x.name: {**cfg.search.bounds, **x.trust} for x in probs}
    starts = {q.name: [dict(q.params)] for _, _, q, _ in pairs}
    starts.update({v.name: [dict(v.params), *w.starts] for _, w, _, v in pairs})
    res = polish(probs, starts, simulate, limits, iters)
    diverged = evaluate(probs, simulate, strict=False)
    out = {}
    for p, w, q, v in pairs:
        held = [i for i, t in enumerate(p.targets) if not t.fit]
        real = [p.targets[i].markers for i in held]
        if v.name not in diverged:  # the winner at its optimum, kept as converge() keeps the final refit
            a = v.summary()
            if refit_kept(p.targets, w.markers, v.markers, w.summary["fit"], a["fit"], cfg.method.gate_z):
                w.params, w.markers, w.summary = dict(v.params), v.markers.copy(), a
        if q.name in diverged:  # nothing to compare with: the winner stands
            out[p.name] = {"ok": True, "why": f"projected null diverged at {diverged[q.name]}"}
            continue
        n_sum = q.summary()
        ev = heldout_z(real, [q.markers[i] for i in held], [w.markers[i] for i in held])
        ok, why = beyond_null(n_sum, w.summary, ev, cfg.method)
        out[p.name] = {**ev, "ok": ok, "why": why, "fit": n_sum["fit"], "heldout": n_sum["heldout"],
                       "params": dict(q.params), "converged": res[q.name].get("converged"),
                       "winner_fit": w.summary["fit"], "winner_heldout": w.summary["heldout"]}
        log.info("loop '%s': %s against its projected null (%s off, the rest re-fitted: fit %.3f px): %s; %s",
                 p.name, "+".join(w.effects), "+".join(w.effects), n_sum["fit"], why, "kept" if ok else "refused")
    return out
