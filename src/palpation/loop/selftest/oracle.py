"""Which injected effects a generative run's data can show: the self-test's identifiability oracle.

An effect drawn at a strength its states cannot show (a weak shell that a stiffer E reproduces to the noise) is no
fault of the search, and naming it would be a guess. So each in-list run's truth is judged as the loop's verdict
judges its own final twin (loop.parsimony.needed, the re-fit step for every effect): at the true parameters, each
injected effect is switched off with what acts through it; if that is significantly worse (gate_z), the rest (E and
the other effects' parameters) is re-fitted by LM from the truth, final_refit_iters steps; an effect whose removal
is then within gate_z on the held-out states is not identifiable in that run. The run's identifiable truth is the
injected set less those. Outside runs are not judged: their in-list truth does not fit their data.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

from palpation.loop.config import LoopConfig
from palpation.loop.effects import EFFECTS
from palpation.loop.parsimony import needed
from palpation.loop.problem import Problem, evaluate
from palpation.loop.real import make_problem
from palpation.loop.selftest.fixed import Injection, base_for
from palpation.measured import load_measured_set

SUFFIX = "=truth"  # a truth problem's name: the run's, so it never meets the run's own problem in a batch


def truth_problem(cfg: LoopConfig, inj: Injection, path: Path, base: Mapping[str, float]) -> Problem:
    """The run's set with the twin at its true parameters, every injected effect on and searched."""
    on, _ = base_for(inj.effects, cfg, base)
    p = make_problem(load_measured_set(path), str(path), cfg, {}, name=inj.name + SUFFIX,
                     holdout=cfg.selftest.holdout, states=cfg.selftest.states, effects_on=[*on, *inj.effects],
                     candidates=[])
    p.params = {**p.params, **inj.params}
    return p


def identifiable(cfg: LoopConfig, injections: list[Injection], paths: list[Path], simulate,
                 base: Mapping[str, float]) -> dict[str, dict]:
    """Per judged run (by tag): {"identifiable": the injected effects the data need, "tests": per effect its z_off,
    z_refit and verdict}. All runs' truths advance in one batch per twin call."""
    judged = [(inj, truth_problem(cfg, inj, path, base)) for inj, path in zip(injections, paths)
              if inj.effects and not inj.unlisted]
    if not judged:
        return {}
    problems = [p for _, p in judged]
    evaluate(problems, simulate)
    effects = {p.name: list(inj.effects) for inj, p in judged}
    tests, _ = needed(problems, simulate, {p.name: cfg.search.bounds for p in problems},
                      cfg.method.final_refit_iters, cfg.method.gate_z, judged=lambda p: effects[p.name])
    out = {}
    for inj, p in judged:
        mine = tests.get(p.name, {})
        # an effect acting only through another (friction through contact) is judged with it where that one goes
        keep = [e for e in inj.effects if mine.get(e, {"needed": True})["needed"]]
        keep = [e for e in keep if all(r in keep for r in EFFECTS[e].requires if r in inj.effects)]
        out[inj.tag] = {"identifiable": keep, "tests": mine}
    return out
