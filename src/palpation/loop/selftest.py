"""Self-test: measured-like sets made by the twin with one hidden effect, then the loop on each.

For every candidate effect and run: draw a strength s in [strength_low, strength_high] nominal steps
(stratified, so the runs of one effect span the range), for a multi-dof effect a random unit direction
over its dofs (positive where only positive is physical), simulate the states with the effect switched on, add detector-like noise (Gaussian,
`noise_px` per coordinate), and save the result in the generic measured format. The loop then reads
each file back knowing only its states and markers, starts from the same twin as every other run,
and says which effect it adds. Effects that need something to touch (friction, mount, ...) are only
visible with surface contact, so the starting twin has `base_effects` on; an injected effect that is
itself a base effect is injected into a twin without it. Every run of a batch advances in lockstep.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from palpation.io import csv_text
from palpation.loop.config import LoopConfig
from palpation.loop.effects import EFFECTS, PARAMS, move
from palpation.loop.engine import Problem, evaluate, initial_params, run_rounds
from palpation.loop.inputs import Target
from palpation.loop.real import make_problem
from palpation.measured import MeasuredState, load_measured_set, make_measured_set, save_measured_set

log = logging.getLogger(__name__)
COLUMNS = ("run", "effect_injected", "strength", "effect_named", "mae_before_px", "mae_after_px")


@dataclass
class Injection:
    run: int
    effect: str
    strength: float
    betas: dict[str, float]  # nominal steps per dof
    base_effects: list[str]
    params: dict[str, float]  # the twin that made the data


def base_for(effect: str, cfg: LoopConfig, base: Mapping[str, float]) -> tuple[list[str], dict[str, float]]:
    """The starting twin of a run: base effects on (minus the injected one, which starts off)."""
    on = [e for e in cfg.selftest.base_effects if e != effect]
    params = initial_params({**base, **cfg.selftest.base_params})
    for e in cfg.selftest.base_effects:
        if e not in on:
            params.update({n: PARAMS[n].default for n in EFFECTS[e].params})
    return on, params


def draw_injections(cfg: LoopConfig, base: Mapping[str, float], rng: np.random.Generator) -> list[Injection]:
    st, steps, out = cfg.selftest, dict(cfg.steps), []
    for effect in st.effects:
        for r in range(st.runs_per_effect):
            on, params = base_for(effect, cfg, base)
            # stratified: run r draws from the r-th of runs_per_effect equal slices of [low, high]
            span = st.strength_high - st.strength_low
            s = float(st.strength_low + span * (r + rng.uniform()) / st.runs_per_effect)
            dofs = EFFECTS[effect].dofs
            u = rng.normal(size=len(dofs))
            # "switched on": a one-dof effect grows; a multi-dof one (camera, mount) goes any way
            u = np.where([d.nonneg or len(dofs) == 1 for d in dofs], np.abs(u), u) / np.linalg.norm(u)
            betas = {d.name: float(s * ui) for d, ui in zip(dofs, u)}
            for d in dofs:
                params = move(params, d, betas[d.name], steps)
            out.append(Injection(len(out), effect, s, betas, on, params))
    return out


def make_sets(injections: list[Injection], states: list[Target], simulate, noise_px: float,
              rng: np.random.Generator, out_dir: Path, geometry: Mapping[str, MeasuredState],
              rest_px: np.ndarray) -> list[Path]:
    """Simulate every injected twin at `states` (one batch), add noise, save each as a measured set."""
    jobs = [(t.state, inj.params) for inj in injections for t in states]
    markers, failed = simulate(jobs)
    if failed.any():
        bad = sorted({injections[i // len(states)].run for i in np.flatnonzero(failed)})
        raise ValueError(f"self-test: the twin diverged while making run(s) {bad}; lower the strengths "
                         "(loop.selftest.strength_high) or the nominal steps (loop.steps)")
    paths = []
    for inj, block in zip(injections, markers.reshape(len(injections), len(states), -1, 2)):
        noisy = block + rng.normal(0.0, noise_px, block.shape)
        mset = make_measured_set(noisy, np.ones(noisy.shape[:2], bool), rest_px,
                                 [geometry[t.name] for t in states], source="palpation.loop.selftest",
                                 detector={"kind": "twin", "noise_px": noise_px})
        path = Path(out_dir) / f"run_{inj.run:03d}"
        save_measured_set(path, mset)
        paths.append(path)
    return paths


def run_selftest(cfg: LoopConfig, simulate, base: Mapping[str, float], template: list[Target],
                 geometry: Mapping[str, MeasuredState], rest_px: np.ndarray, out_dir: Path, db_path: Path,
                 tkey: str, progress: bool = False) -> tuple[list[dict], list[Problem], list[Injection]]:
    """Make the sets, run the loop on each (it only reads the files), and score what it names.

    The runs advance in lockstep: `progress` shows their rounds and, per recalibration, the trials of
    all runs together."""
    cfg.validate()
    rng = np.random.default_rng(cfg.selftest.seed)
    injections = draw_injections(cfg, base, rng)
    paths = make_sets(injections, template, simulate, cfg.selftest.noise_px, rng, Path(out_dir) / "sets",
                      geometry, rest_px)
    problems = []
    for inj, path in zip(injections, paths):
        mset = load_measured_set(path)
        _, start = base_for(inj.effect, cfg, base)
        p = make_problem(mset, str(path), cfg, {}, name=f"run{inj.run:03d}", holdout=cfg.selftest.holdout,
                         states=cfg.selftest.states, effects_on=inj.base_effects, candidates=cfg.effects)
        p.params = dict(start)
        problems.append(p)
    evaluate(problems, simulate)
    before = [p.summary() for p in problems]
    run_rounds(problems, simulate, cfg, db_path, tkey, cfg.selftest.max_rounds, progress=progress)
    rows = []
    for inj, p, b in zip(injections, problems, before):
        added = [r["effect"] for r in p.rounds if r["accepted"] and r["effect"]]
        first = p.rounds[0] if p.rounds else {}
        rows.append({"run": inj.run, "effect_injected": inj.effect, "strength": inj.strength,
                     "effect_named": added[0] if added else "none", "mae_before_px": b["all"],
                     "mae_after_px": p.summary()["all"], "attribution_top": first.get("effect") or "none",
                     "share_explained": first.get("share_explained", 0.0), "betas": inj.betas,
                     "injected": {k: inj.params[k] for e in [inj.effect] for k in EFFECTS[e].params},
                     "recovered": {k: p.params[k] for e in [inj.effect] for k in EFFECTS[e].params}})
    return rows, problems, injections


def confusion(rows: list[dict], effects: list[str]) -> dict[str, dict[str, int]]:
    names = list(effects) + ["none"]
    table = {e: {n: 0 for n in names} for e in effects}
    for r in rows:
        table[r["effect_injected"]][r["effect_named"] if r["effect_named"] in names else "none"] += 1
    return table


def summary(rows: list[dict]) -> dict:
    cut = [1.0 - r["mae_after_px"] / r["mae_before_px"] for r in rows if r["mae_before_px"] > 0]
    return {"runs": len(rows), "named_correctly": float(np.mean([r["effect_named"] == r["effect_injected"]
                                                                 for r in rows])),
            "mae_cut_mean": float(np.mean(cut)),
            "mae_before_mean_px": float(np.mean([r["mae_before_px"] for r in rows])),
            "mae_after_mean_px": float(np.mean([r["mae_after_px"] for r in rows]))}


def rows_csv(rows: list[dict]) -> str:
    return csv_text(rows, COLUMNS, digits=4)
