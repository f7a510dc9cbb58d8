"""One self-test run's final stage on the CPU, from where a (GPU) self-test left it (docs/journal/2026-11-26-loop-heldout-seed-stalls.md).

    PYTHONPATH=src python workflow/scripts/loop_stall_rerun.py OUTDIR RUN MODE [--mesh M] [--measured S]

OUTDIR: a self-test's output (hydra/.hydra/overrides.yaml, selftest.json). The run's set is re-made exactly from the
seed (selftest.remake_set). The end point is rebuilt from selftest.json: the injected effects' recovered parameters,
every named effect not injected at its off value (their fitted values are not saved), E re-fitted alone (not saved
either). Then the final refit (refit.converge through unexplained.check_all) and the final check, with MODE: `lm` (no
camera grid), `grid` (loop.method.camera_grid_converged: the rotation grid at that point) or `regrid`
(+ loop.method.final_refit_regrid=2 loop.method.final_refit_off_starts=true). Prints the fits, the end point and the verdict.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import palpation.apps.loop  # noqa: F401  (registers the loop's structured configs)
from palpation.loop.effects import EFFECTS, PARAMS
from palpation.loop.inputs import load_targets
from palpation.loop.polish import polish
from palpation.loop.problem import evaluate
from palpation.loop.real import make_problem
from palpation.loop.selftest.fixed import base_for, remake_set
from palpation.loop.simulate import LoopSimulator, loop_twin_config
from palpation.loop.start import nominal_projection, start_twin
from palpation.loop.unexplained import check_all, noise_estimate
from palpation.markers.template import rest_template
from palpation.measured import load_measured_set
from palpation.paths import REPO_ROOT
from palpation.twin.mesh import SensorMesh

DROP = ("twin.device", "out.dir", "loop.search.ask_workers", "mesh", "measured", "track", "progress")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("run", type=int)
    ap.add_argument("mode", choices=("lm", "grid", "regrid"))
    ap.add_argument("--mesh", default="results/twin/mesh_coarse.npz")
    ap.add_argument("--measured", default="results/data/photos/measured_photos")
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    over = a.outdir / "hydra" / ".hydra" / "overrides.yaml"
    if not over.is_file():
        raise SystemExit(f"{over} missing: OUTDIR must be a self-test's output (gpu_loop_selftest.sh keeps hydra/)")
    ov = [ln[2:].strip() for ln in over.read_text().splitlines() if ln.startswith("- ")]
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="loop", overrides=[o for o in ov if o.split("=")[0] not in DROP])
    loop = OmegaConf.to_object(cfg.loop).validate()
    twin = OmegaConf.to_object(cfg.twin)
    rows = json.loads((a.outdir / "selftest.json").read_text())["rows"]
    if not 0 <= a.run < len(rows):
        raise SystemExit(f"{a.outdir}/selftest.json has runs 0..{len(rows) - 1}, not {a.run}")
    row = rows[a.run]
    _, start = start_twin(twin, loop.shell_thickness_mm * 1e-3)
    mset = load_measured_set(a.measured)
    tw = loop_twin_config(nominal_projection(twin), loop.shell_thickness_mm * 1e-3)
    sim = LoopSimulator(SensorMesh.load(a.mesh), tw, rest_template(), device="cpu", split_by_kind=True)
    st = loop.selftest
    template = load_targets(mset, str(a.measured), [], st.states, loop.twist_z_angle)
    inj, ms = remake_set(loop, start, template, sim.simulate, a.run, {s.name: s for s in mset.states}, mset.rest)
    print("injected", inj.label, {k: inj.params[k] for e in inj.effects for k in EFFECTS[e].params})
    on, _ = base_for(inj.effects, loop, start)
    p = make_problem(ms, "remade", loop, {}, name=f"run{a.run:03d}", holdout=st.holdout, states=st.states,
                     effects_on=on, candidates=loop.effects)
    p.noise_px = noise_estimate(ms, loop.noise_px)[0]
    p.params = dict(inj.params)
    evaluate([p], sim.simulate)
    print("truth:", p.summary())
    named = row["named"]
    p.params.update({n: PARAMS[n].default for e in named for n in EFFECTS[e].params})  # not injected: off
    p.params.update(row["recovered"])
    p.searched = ["E"]
    polish([p], {p.name: [dict(p.params)]}, sim.simulate, {p.name: dict(loop.search.bounds)}, loop.method.final_refit_iters)
    evaluate([p], sim.simulate)
    print("end point (E re-fitted alone):", p.params["E"], p.summary())
    p.effects, p.candidates = list(named), [c for c in loop.effects if c not in named]
    p.searched = ["E", *[n for e in named for n in EFFECTS[e].params]]
    loop.method.camera_grid_converged = a.mode != "lm"
    loop.method.final_refit_regrid = 2 if a.mode == "regrid" else 0
    loop.method.final_refit_off_starts = a.mode == "regrid"
    t = time.time()
    check_all([p], sim.simulate, loop, {p.name: p.noise_px})
    print(a.mode, "final refit:", p.final.get("refit"), f"{time.time() - t:.0f} s")
    print("end:", {k: p.params[k] for k in p.searched})
    print("final check:", {k: p.final["test"][k] for k in ("excess_ratio", "p_value", "unexplained")})


if __name__ == "__main__":
    main()
