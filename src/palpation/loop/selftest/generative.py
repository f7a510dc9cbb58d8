"""Generative self-test: every run draws its own truth, so the measure is not the list the loop was built on.

Run r of seed s draws from np.random.default_rng([s, r]) alone (settings: loop.generative, GenerativeConfig):
1. with probability `unlisted_share`, one outside effect: a kind of the library (loop.unlisted) and its strength;
2. the number of in-list effects n ~ `n_effects` (P(0), ..., P(3)); effects are taken in a random order from the
   candidates (loop.effects, less selftest.base_effects), each with what it requires (friction brings surface
   contact, which counts), until n are in (one that would overshoot is passed over);
3. the base twin's E, log-uniform in `E`, and where contact is on the contact stiffness k_s, log-uniform in `k_s`;
4. every other in-list effect's strength, log-uniform in its [detectable, stable] range (nominal steps), a
   multi-dof one along a random direction (fixed.switch_on, as the fixed self-test);
5. then, making the set: the outside effect's own draws and the detector noise, from the same stream.
A draw whose twin diverges is drawn again from default_rng([s, r, attempt]) (fixed.simulate_injections).
Everything after the draw is the fixed self-test's: the set is saved and read back, the loop starts from the
real mode's twin (fixed.base_for: E 1.2225 MPa, no contact) and runs up to `max_rounds` rounds, all runs of a
batch in lockstep (fixed.loop_on_sets). Dev seeds (< 1000) choose mechanisms and thresholds; test seeds
(>= 1000) choose nothing and are run once, at the end, with the same settings.

Timing: each batch's wall time is appended to <out>/timing.json (apart from the runs, whose records stay
byte-identical for a seed). Resumable: each finished run is saved atomically as <out>/runs/<split>_seed<s>_run<r>.json with a fingerprint of
every setting that shapes a run (not the split, seeds, run count or batch size); a run whose file carries the
current fingerprint is skipped, and the CSV is assembled from every saved run with that fingerprint.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import time
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from palpation.io import csv_text, save_json
from palpation.loop.config import LoopConfig
from palpation.loop.effects import EFFECTS
from palpation.loop.generative_config import SPLITS, TEST_SEED_START
from palpation.loop.inputs import Target
from palpation.loop.selftest.fixed import (Injection, base_for, loop_on_sets, make_sets, simulate_injections,
                                           switch_on)
from palpation.loop.selftest.oracle import identifiable
from palpation.measured import MeasuredState

log = logging.getLogger(__name__)
COLUMNS = ("run", "seed", "split", "effects_injected", "effects_named", "mae_before_px", "mae_after_px",
           "excess_ratio", "params_true", "params_fitted")
CONTACT = "surface_contact"


def split_of(seed: int) -> str:
    return "dev" if seed < TEST_SEED_START else "test"


def tag(seed: int, run: int) -> str:
    return f"{split_of(seed)}_seed{seed}_run{run}"


def log_uniform(rng: np.random.Generator, low: float, high: float) -> float:
    return float(np.exp(rng.uniform(np.log(low), np.log(high))))


def pick_effects(candidates: list[str], n: int, rng: np.random.Generator, present=()) -> list[str]:
    """Up to n effects of `candidates`, taken in a random order, each with the effects it requires (they count;
    `present`: already on, they do not). One whose requirements would overshoot n, or are no candidate, is passed
    over. In `candidates` order."""
    chosen: list[str] = []
    for e in (str(x) for x in rng.permutation(candidates)):
        if len(chosen) >= n:
            break
        if e in chosen:
            continue
        need = [r for r in EFFECTS[e].requires if r not in chosen and r not in present]
        if all(r in candidates for r in need) and len(chosen) + len(need) + 1 <= n:
            chosen += [*need, e]
    return [e for e in candidates if e in chosen]


def draw(cfg: LoopConfig, base: Mapping[str, float], seed: int, run: int, attempt: int = 0) -> Injection:
    """The truth of run `run` of `seed` (module docstring), from its own stream; `attempt` > 0: a redraw."""
    g, steps = cfg.generative, dict(cfg.method.steps)
    rng = np.random.default_rng([seed, run, attempt] if attempt else [seed, run])
    kinds = sorted(g.unlisted)
    outside = kinds[int(rng.integers(len(kinds)))] if kinds and rng.uniform() < g.unlisted_share else None
    p = np.asarray(g.n_effects, float)
    n = int(rng.choice(len(p), p=p / p.sum()))
    present = cfg.selftest.base_effects
    inl = pick_effects([e for e in cfg.effects if e not in present], n, rng, present)
    on, params = base_for(inl, cfg, base)
    params["E"] = log_uniform(rng, *g.E)
    k_s = log_uniform(rng, *g.k_s) if CONTACT in inl or CONTACT in present else None
    strengths, betas = {}, {}
    for e in inl:
        # contact's strength is its stiffness in nominal steps (one dof, k_s 0 -> step)
        strengths[e] = k_s / steps.get("k_s", EFFECTS[CONTACT].dofs[0].moves[0][2]) if e == CONTACT \
            else log_uniform(rng, *g.strengths[e])
        params = switch_on(params, e, strengths[e], rng, steps, betas)
    if k_s is not None:
        params["k_s"] = k_s  # exactly the drawn value (the step's round trip can move the last digit)
    unl = [outside] if outside else []
    for u in unl:
        strengths[u] = log_uniform(rng, *g.unlisted[u])
    return Injection(run, inl, unl, strengths, betas, on, params, redrawn=attempt, tag=tag(seed, run), rng=rng)


def truth_keys(inj: Injection) -> list[str]:
    """E, the contact stiffness, then every searched parameter of the injected in-list effects."""
    return list(dict.fromkeys(["E", "k_s", *(n for e in inj.effects for n in EFFECTS[e].params)]))


def _params_json(params: Mapping[str, float], keys: list[str]) -> str:
    return json.dumps({k: float(f"{float(params[k]):.6g}") for k in keys})


def fingerprint(cfg: LoopConfig, tkey: str, base: Mapping[str, float], rest_px: np.ndarray,
                geometry: Mapping[str, MeasuredState]) -> str:
    """Hash of what shapes a run (its truth, its set, the loop on it); not which runs are made, nor how they are
    batched or proposed (neither changes a run: loop.simulate, loop.recalibrate)."""
    d = dataclasses.asdict(cfg)
    for k in ("split", "dev_seeds", "test_seeds", "runs", "batch"):
        d["generative"].pop(k)
    for k in ("cases", "runs_per_case", "strength_low", "strength_high", "noise_px", "max_rounds", "seed"):
        d["selftest"].pop(k)  # the fixed self-test's own
    d["search"].pop("ask_workers")
    d.pop("split_by_kind")
    blob = json.dumps({"loop": d, "twin": tkey, "base": dict(base), "geometry": sorted(map(repr, geometry.values())),
                       "rest": hashlib.sha1(np.ascontiguousarray(rest_px, np.float64).tobytes()).hexdigest()},
                      sort_keys=True, default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def saved(runs_dir: Path, fp: str) -> dict[str, dict]:
    """Every finished run with fingerprint `fp`, by tag (a file that does not parse is redone)."""
    out = {}
    for path in sorted(Path(runs_dir).glob("*.json")):
        try:
            record = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            log.warning("generative self-test: %s unreadable (%s); the run is made again", path, exc)
            continue
        if record.get("fingerprint") == fp:
            out[path.stem] = record
    return out


def record(inj: Injection, seed: int, row: dict, fitted: Mapping[str, float], fp: str,
           oracle: Mapping | None = None) -> dict:
    """One finished run: the CSV row (COLUMNS), what the summary reads and, for an in-list run, the oracle's
    identifiable truth (loop.selftest.oracle)."""
    keys = truth_keys(inj)  # the fitted side also gives every named effect's parameters (a spurious one's too)
    named = list(dict.fromkeys([*keys, *(n for e in row["named"] for n in EFFECTS[e].params)]))
    out = {"run": inj.run, "seed": seed, "split": split_of(seed), "effects_injected": inj.label or "none",
           **{k: row[k] for k in ("effects_named", "mae_before_px", "mae_after_px", "excess_ratio")},
           "params_true": _params_json(inj.params, keys), "params_fitted": _params_json(fitted, named)}
    detail = {k: row[k] for k in ("injected_effects", "unlisted", "named", "unexplained", "strengths", "betas",
                                  "redrawn", "tries")}
    # what the rounds kept before loop.parsimony took out what the final twin does not need (both verdicts kept)
    detail.update({k: row[k] for k in ("named_by_rounds", "parsimony") if k in row})
    return {"fingerprint": fp, **out, **detail, "n_effects": len(inj.effects), **judged(inj, oracle)}


def judged(inj: Injection, oracle: Mapping | None) -> dict:
    """The oracle's fields of a run's record: none for an outside run, an empty truth for a run with none."""
    if inj.unlisted:
        return {}
    if not inj.effects:
        return {"identifiable": [], "oracle": {}}
    return {"identifiable": oracle["identifiable"], "oracle": oracle["tests"]} if oracle else {}


def needs_oracle(rec: Mapping) -> bool:
    """A saved in-list run from before the oracle (its record is completed on resume: loop.selftest.oracle)."""
    return "identifiable" not in rec and not rec["unlisted"]


def log_batch(path: Path, fp: str, tags: list[str], wall_s: float) -> None:
    """Append one batch's wall time (settings, runs, seconds) to `path`, a JSON list (an unreadable one restarts)."""
    try:
        batches = json.loads(path.read_text()) if path.exists() else []
    except ValueError:
        batches = []
    batches.append({"fingerprint": fp, "runs": tags, "wall_s": round(wall_s, 1)})
    save_json(path, batches)


def run_sets(cfg: LoopConfig, base: Mapping[str, float], draws: list[tuple[int, int, int]], simulate,
             template: list[Target], geometry: Mapping[str, MeasuredState], rest_px: np.ndarray, out_dir: Path,
             rest_of) -> tuple[list[Injection], list[Path]]:
    """The runs' truths (seed, run, attempt) drawn, simulated (a diverged one drawn again), their outside effects
    and noise added, and their sets saved under <out>/sets; returns the injections and the sets' paths."""
    seed_of = {tag(s, r): s for s, r, _ in draws}
    injections = [draw(cfg, base, s, r, attempt) for s, r, attempt in draws]
    markers = simulate_injections(injections, template, simulate, cfg, base,
                                  lambda inj, attempt: draw(cfg, base, seed_of[inj.tag], inj.run, attempt))
    for inj in injections:
        inj.rest = rest_of(inj.params) if rest_of else None
    return injections, make_sets(injections, markers, template, cfg.generative.noise_px, None, Path(out_dir) / "sets",
                                 geometry, rest_px)


def run_generative(cfg: LoopConfig, simulate, base: Mapping[str, float], template: list[Target],
                   geometry: Mapping[str, MeasuredState], rest_px: np.ndarray, out_dir: Path, db_path: Path,
                   tkey: str, rest_of: Callable[[Mapping[str, float]], np.ndarray] | None = None,
                   progress: bool = False) -> list[dict]:
    """Make and score every run of the split's seeds not yet saved, `batch` runs at a time; return every saved
    run of these settings (both splits where both were made into `out_dir`), dev first, by seed and run.
    `rest_of(params)`: the rest markers of a twin (loop.unlisted.twin_rest), for the outside physical kinds."""
    g = cfg.validate().generative.validate(cfg)
    out_dir = Path(out_dir)
    runs_dir = out_dir / "runs"
    fp = fingerprint(cfg, tkey, base, rest_px, geometry)
    done = saved(runs_dir, fp)
    todo = [(s, r) for s in g.seeds() for r in range(g.runs) if tag(s, r) not in done]
    log.info("generative self-test (%s, seeds %s, %d runs each, settings %s): %d saved, %d to make", g.split,
             g.seeds(), g.runs, fp, len(g.seeds()) * g.runs - len(todo), len(todo))
    size = g.batch or max(len(todo), 1)
    for i in range(0, len(todo), size):
        start = time.perf_counter()
        chunk = todo[i:i + size]
        seed_of = {tag(s, r): s for s, r in chunk}
        injections, paths = run_sets(cfg, base, [(s, r, 0) for s, r in chunk], simulate, template, geometry, rest_px,
                                     out_dir, rest_of)
        rows, problems = loop_on_sets(cfg, injections, paths, simulate, base, db_path, tkey, g.max_rounds, progress)
        oracle = identifiable(cfg, injections, paths, simulate, base)
        for inj, row, p in zip(injections, rows, problems):
            save_json(runs_dir / f"{inj.tag}.json", record(inj, seed_of[inj.tag], row, p.params, fp,
                                                           oracle.get(inj.tag)))
        log_batch(out_dir / "timing.json", fp, [inj.tag for inj in injections], time.perf_counter() - start)
        log.info("generative self-test: runs %s saved", [inj.tag for inj in injections])
    backfill_oracle(cfg, simulate, base, template, geometry, rest_px, out_dir, fp, rest_of, g.batch)
    order = {s: i for i, s in enumerate(SPLITS)}
    return sorted(saved(runs_dir, fp).values(), key=lambda r: (order[r["split"]], r["seed"], r["run"]))


def backfill_oracle(cfg: LoopConfig, simulate, base: Mapping[str, float], template: list[Target],
                    geometry: Mapping[str, MeasuredState], rest_px: np.ndarray, out_dir: Path, fp: str,
                    rest_of, batch: int) -> None:
    """Complete saved in-list runs made before the oracle: each set is re-made from its seed (the twin on this
    device; a set made on another differs by the device's floats) and its truth judged; the loop is not re-run.
    `batch` runs at a time (0: all at once)."""
    runs_dir = out_dir / "runs"
    stale = [r for r in saved(runs_dir, fp).values() if needs_oracle(r)]
    size = batch or max(len(stale), 1)
    if stale:
        log.info("generative self-test: %d saved runs get the identifiability oracle", len(stale))
    for i in range(0, len(stale), size):
        chunk = stale[i:i + size]
        injections, paths = run_sets(cfg, base, [(r["seed"], r["run"], r["redrawn"]) for r in chunk], simulate,
                                     template, geometry, rest_px, out_dir, rest_of)  # the draw each was made of
        oracle = identifiable(cfg, injections, paths, simulate, base)
        for inj, rec in zip(injections, chunk):
            save_json(runs_dir / f"{inj.tag}.json", {**rec, **judged(inj, oracle.get(inj.tag))})


def rows_csv(records: list[dict]) -> str:
    nan = float("nan")  # a non-finite number was saved as null (palpation.io.save_json)
    rows = [{**r, **{k: nan if r[k] is None else r[k] for k in ("mae_before_px", "mae_after_px", "excess_ratio")}}
            for r in records]
    return csv_text(rows, COLUMNS, digits=4)
