"""Parsimony in the verdict: an effect the rounds added stays named only if the final twin needs it.

The rounds keep an effect when its try passes the gate against the twin before it; by the end a later effect or
the final refit may have taken over its part, or its parameters may have returned to their off values (a layered
shell ratio back at 1.0, a viscous alpha at the base value), and the report still named it. After the final refit
every added effect (with the effects that act through it: friction goes with contact) is taken out:
1. switched off at the final parameters, the twin simulated at every state: if it is not significantly worse on
   the states (cluster z of gate.heldout_z <= z_crit), the effect is inert and goes;
2. else the rest re-fitted from there (LM, loop.polish, final_refit_iters steps): if the held-out states (the fitted
   ones where the set has none) are then not significantly worse than the final twin's, the effect was not
   needed and goes.
Before both, an added effect held less than loop.method.min_strength_steps nominal steps from off (effects.strength;
surface contact aside, see CARRIERS) goes without a test: a significance test at a noise floor this low would keep
a term of hundredths of a millimetre that only evens out what the rest's fit left (its uncertainty is smaller
still). The least needed effect goes first and the rest are tested again; an effect that goes leaves the named set,
the searched parameters and the twin file (its parameters back at their off values). Effects the starting twin had
are not judged. Each problem's record lands in p.parsimony. Which sets get step 2 is loop.method.prune's choice
(loop.unexplained.check_all): none ("inert": step 1 only), the sets still above the noise, or all.
"""

from __future__ import annotations

import copy
import logging
from typing import Callable, Mapping

from palpation.loop.effects import EFFECTS, PARAMS, strength
from palpation.loop.gate import heldout_z
from palpation.loop.polish import polish
from palpation.loop.problem import evaluate

log = logging.getLogger(__name__)
# effects others act through (surface contact): their parameter switches a mechanism on, it does not measure its size
# (any contact stiffness brings the surface into play), so only the removal tests judge them
CARRIERS = {r for e in EFFECTS.values() for r in e.requires}


def added_effects(p) -> list[str]:
    """Effects the rounds added and the twin still has, in the order they came."""
    added = [e for r in p.rounds if r.get("accepted") for e in r.get("effects", [])]
    return [e for e in dict.fromkeys(added) if e in p.effects]


def removal_set(p, effect: str) -> list[str]:
    """`effect` and the twin's effects that act only through it."""
    return [effect, *(e for e in p.effects if effect in EFFECTS[e].requires)]


def without(p, effects: list[str]):
    """A copy of problem p with `effects` switched off: their parameters at off, no longer searched."""
    q = copy.copy(p)
    gone = {n for e in effects for n in EFFECTS[e].params}
    q.name = f"{p.name}~{'+'.join(effects)}"
    q.params = {**p.params, **{n: PARAMS[n].default for n in gone}}
    q.effects = [e for e in p.effects if e not in effects]
    q.searched = [n for n in p.searched if n not in gone]
    q.markers = None
    return q


def _z(p, q, heldout: bool) -> float:
    """How much better p's twin is than q's (cluster z over the held-out states, else over all of them)."""
    ix = [i for i, t in enumerate(p.targets) if not t.fit] if heldout else []
    ix = ix or list(range(len(p.targets)))
    return heldout_z([p.targets[i].markers for i in ix], [q.markers[i] for i in ix],
                     [p.markers[i] for i in ix])["z"]


def needed(problems: list, simulate, limits: Mapping[str, Mapping | None], iters: int, z_crit: float,
           judged: Callable[[object], list[str]] = added_effects) -> tuple[dict, dict]:
    """Per problem, per judged effect (default: the added ones): {"z_off": z at the final parameters, "z_refit": z
    after re-fitting the rest (None where step 1 settled it), "needed": bool}; and the problem without each effect
    with what that took out, {(name, effect): (copy, effects)}."""
    tests = [(p, e, without(p, removal_set(p, e))) for p in problems for e in judged(p)]
    if not tests:
        return {}, {}
    diverged = evaluate([q for _, _, q in tests], simulate, strict=False)
    out: dict[str, dict] = {}
    refit = []
    for p, e, q in tests:
        z = float("inf") if q.name in diverged else _z(p, q, heldout=False)
        out.setdefault(p.name, {})[e] = {"z_off": z, "z_refit": None, "needed": z > z_crit}
        if z > z_crit and q.name not in diverged and q.searched and iters > 0:
            refit.append((p, e, q))
    if refit:
        polish([q for _, _, q in refit], {q.name: [dict(q.params)] for _, _, q in refit}, simulate,
               {q.name: limits.get(p.name) for p, _, q in refit}, iters)
        bad = evaluate([q for _, _, q in refit], simulate, strict=False)
        for p, e, q in refit:
            if q.name not in bad:
                z = _z(p, q, heldout=True)
                out[p.name][e].update(z_refit=z, needed=z > z_crit)
    return out, {(p.name, e): (q, removal_set(p, e)) for p, e, q in tests}


def drop_negligible(problems: list, simulate, min_steps: float) -> None:
    """Take out every added effect held less than `min_steps` nominal steps from off, with what acts only through
    it when that is negligible too (p.parsimony["negligible"])."""
    changed = []
    for p in problems:
        small = [e for e in added_effects(p) if e not in CARRIERS
                 and all(strength(x, p.params) < min_steps for x in removal_set(p, e))]
        gone = list(dict.fromkeys(x for e in small for x in removal_set(p, e)))
        if gone:
            q = without(p, gone)
            p.params, p.effects, p.searched, p.markers = q.params, q.effects, q.searched, None
            p.parsimony["dropped"] += gone
            p.parsimony["negligible"] = gone
            changed.append(p)
            log.info("loop '%s': %s taken out of the final twin, negligible (< %.2g nominal steps from off)", p.name,
                     "+".join(gone), min_steps)
    if changed:
        evaluate(changed, simulate)


def prune(problems: list, simulate, limits: Mapping[str, Mapping | None], iters: int, z_crit: float,
          min_steps: float = 0.0) -> None:
    """Take out the negligible added effects, then, one at a time and least needed first, every added effect the
    final twin does not need (see the module docstring); p.parsimony records each pass's tests and what went."""
    for p in problems:
        p.parsimony = {"passes": [], "dropped": []}
    drop_negligible(problems, simulate, min_steps)
    todo = [p for p in problems if added_effects(p)]
    while todo:
        tests, shadows = needed(todo, simulate, limits, iters, z_crit)
        going = []
        for p in todo:
            mine = tests.get(p.name, {})
            p.parsimony["passes"].append(mine)
            spare = {e: t["z_off"] if t["z_refit"] is None else t["z_refit"] for e, t in mine.items() if not t["needed"]}
            if not spare:
                continue
            worst = min(spare, key=spare.get)
            q, gone = shadows[(p.name, worst)]  # its markers are current (simulated after its refit, if any)
            p.params, p.effects, p.searched, p.markers = q.params, q.effects, q.searched, q.markers
            p.parsimony["dropped"] += gone
            log.info("loop '%s': %s taken out of the final twin, not needed (z %.2f without it <= %.1f)", p.name,
                     "+".join(gone), spare[worst], z_crit)
            going.append(p)
        todo = [p for p in going if added_effects(p)]
