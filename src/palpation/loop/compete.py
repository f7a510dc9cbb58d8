"""Effect sets of one round compete (issue 13): the first set that passes the gate is not kept blindly.

The 60-run self-test (H100, 88516d9) lost most of its misses to the order of a round's plan: a wrong single
effect ranked first passed the gate and ended the round, so the set that explains the data was never tried
(contact + strong friction: the camera took 32 -> 17 px and the pair was never fitted), or a set with more
parameters reached the noise level first and an equally good smaller one was never tried (viscous lag named
as a 3-parameter mount tilt). So a set that passes the gate becomes the round's *winner*, and the round goes
on with the plan items that could still beat it:

* larger sets (more effects), only while the winner leaves a residual above the noise on the fitted states
  (RMS per coordinate > `unexplained_ratio` x sigma, the size the final check calls unexplained): below it
  there is nothing left for a larger set to explain;
* smaller sets (fewer effects, then fewer parameters), which win a tie (parsimony, as the BIC does).

A later set that passes the gate (against the previous twin and the null try) replaces the winner only if
it also passes the same gate against the winner (same rule, same thresholds: `loop.gate.decide`), or if the
two are indistinguishable (neither passes against the other) and it is smaller; an indistinguishable pair is
named in the record either way (the honest outcome on states that cannot separate them).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from palpation.loop.effects import EFFECTS
from palpation.loop.gate import decide, heldout_z


def size(effects) -> tuple[int, int]:
    """(effects, parameters) of an effect set: the parsimony order."""
    return len(effects), sum(len(EFFECTS[e].params) for e in effects)


@dataclass
class Winner:
    effects: tuple[str, ...]
    record: dict  # its round record (accepted turns False if it is replaced)
    params: dict
    markers: np.ndarray
    searched: list[str]
    starts: list[dict]
    summary: dict
    indistinguishable: list[str] = field(default_factory=list)


def residual_rms(summary: dict, n_coords: int) -> float:
    """RMS per coordinate of the fitted states' residual (from Problem.summary's fit_energy)."""
    return float(np.sqrt(summary["fit_energy"] / max(n_coords, 1)))


def at_noise(summary: dict, n_coords: int, sigma: float | None, ratio: float) -> bool:
    """The fitted residual is within `ratio` x sigma per coordinate (sigma unknown: never)."""
    return sigma is not None and np.isfinite(sigma) and residual_rms(summary, n_coords) <= ratio * sigma


def worth_trying(effects, winner: Winner, noise_level: bool) -> bool:
    """Can this plan item still replace the winner? Smaller sets always; larger only above the noise."""
    mine, theirs = size(effects), size(winner.effects)
    return mine < theirs or (not noise_level and mine[0] > theirs[0])


def challenge(targets, winner: Winner, effects, summary: dict, markers: np.ndarray, cfg) -> tuple[bool, str]:
    """(replace the winner?, why): the gate of the candidate against the winner, and back."""
    held = [i for i, t in enumerate(targets) if not t.fit]
    real = [targets[i].markers for i in held]
    args = (cfg.method.min_improvement_px, cfg.method.min_improvement_rel, cfg.method.gate_fit_rel, cfg.method.gate_z)
    w = "+".join(winner.effects)
    ok, why = decide(winner.summary, summary, heldout_z(real, [winner.markers[i] for i in held],
                                                        [markers[i] for i in held]), *args)
    if ok:
        return True, f"better than {w} ({why})"
    back, why_back = decide(summary, winner.summary, heldout_z(real, [markers[i] for i in held],
                                                               [winner.markers[i] for i in held]), *args)
    if back:
        return False, f"{w} stays: it passes the gate against this set ({why_back})"
    if size(effects) < size(winner.effects):
        return True, f"indistinguishable from {w} (neither passes the gate against the other); fewer parameters"
    return False, f"indistinguishable from {w} (neither passes the gate against the other); {w} is not larger"


def enter(cfg, p, queue: dict, attempt: int, winners: dict, item: dict, rec: dict, a: dict, starts: list) -> bool:
    """A set of problem `p` that passed the gate (record `rec`, summary `a`): the round's winner, or a
    challenger of it; the rest of the round's plan (queue) is cut to what could still beat the winner.
    Returns whether it is the winner now (the engine applies the winner when the round ends)."""
    effects = tuple(item["effects"])
    label = "+".join(effects)
    mine = Winner(effects, rec, dict(p.params), p.markers.copy(), list(p.searched), starts, a)
    w = winners.get(p.name)
    if w is not None:
        replace, why = challenge(p.targets, w, effects, a, p.markers, cfg)
        tie = "indistinguishable" in why
        if not replace:
            if tie:
                w.indistinguishable.append(label)
                w.record["indistinguishable"] = list(w.indistinguishable)
            rec["accepted"] = False
            rec["after"]["gate"]["why"] += f"; passed, but {why}"
            return False
        mine.indistinguishable = [*w.indistinguishable, "+".join(w.effects)] if tie else []
        rec["indistinguishable"] = list(mine.indistinguishable)
        w.record["accepted"] = False
        w.record["after"]["gate"]["why"] += f"; replaced by {label}"
        rec["after"]["gate"]["why"] += f"; {why}"
    winners[p.name] = mine
    if not cfg.method.compete:
        queue[p.name] = []  # the first set that passes is kept (the loop before issue 13's competition)
        return True
    n = sum(t.fit for t in p.targets) * p.markers.shape[1] * 2
    quiet = at_noise(a, n, p.noise_px, cfg.method.unexplained_ratio)
    q = queue[p.name]
    queue[p.name] = q[:attempt + 1] + [it for it in q[attempt + 1:] if worth_trying(it["effects"], mine, quiet)]
    return True
