"""The final check's two rules on saved generative runs, without re-running the loop.

    python workflow/scripts/loop_verdict_rescore.py RUNS_DIR OUT_CSV [Hydra overrides of conf/loop.yaml]

Each saved run (RUNS_DIR/*.json, a generative self-test's generative/runs) is re-made from its seed (the twin on
this device; a set made on another differs by the device's floats), its final twin rebuilt from the record (the named
effects on, the fitted parameters), and the final check (loop.unexplained.final_check) computed beyond the twin and
beyond every candidate. The verdict is the loop's last step and feeds nothing back, so this is the rule the loop
would have applied to the same final twin. OUT_CSV: run, seed, unlisted, injected, named, exact, unexplained_twin,
unexplained_candidates, excess_twin, excess_candidates, explained_by_candidates.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pandas as pd
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from palpation.apps.loop import loop_simulator
from palpation.loop.config import LoopConfig
from palpation.loop.engine import refit_dofs, signatures
from palpation.loop.inputs import load_targets
from palpation.loop.problem import evaluate
from palpation.loop.real import make_problem
from palpation.loop.selftest.fixed import base_for
from palpation.loop.selftest.generative import run_sets
from palpation.loop.unexplained import final_check, noise_estimate
from palpation.loop.unlisted import twin_rest
from palpation.measured import load_measured_set
from palpation.paths import REPO_ROOT
from palpation.twin.config import TwinConfig
from palpation.twin.mesh import SensorMesh


def main(runs_dir: Path, out_csv: Path, overrides: list[str]) -> None:
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="loop", overrides=["mode=generative", *overrides])
    loop: LoopConfig = OmegaConf.to_object(cfg.loop).validate()
    twin: TwinConfig = OmegaConf.to_object(cfg.twin)
    records = sorted((json.loads(f.read_text()) for f in Path(runs_dir).glob("*.json")),
                     key=lambda r: (r["seed"], r["run"]))
    mset = load_measured_set(cfg.measured)
    mesh = SensorMesh.load(cfg.mesh)
    _, sim = loop_simulator(twin, loop, mesh)
    template = load_targets(mset, str(cfg.measured), [], loop.selftest.states, loop.twist_z_angle)
    geometry = {s.name: s for s in mset.states}
    binding_rest = sim.binding({}).anchor_px
    injections, paths = run_sets(loop, {}, [(r["seed"], r["run"], r["redrawn"]) for r in records], sim.simulate,
                                 template, geometry, mset.rest, out_csv.parent / "rescore",
                                 lambda p: twin_rest(binding_rest, sim.template, p))
    problems, sigmas = [], {}
    for rec, inj, path in zip(records, injections, paths):
        on, _ = base_for(inj.effects, loop, {})
        m = load_measured_set(path)
        p = make_problem(m, str(path), loop, {}, name=inj.name, holdout=loop.selftest.holdout,
                         states=loop.selftest.states, effects_on=[*on, *rec["named"]], candidates=loop.effects)
        p.params = {**p.params, **json.loads(rec["params_fitted"])}
        sigmas[p.name] = noise_estimate(m, loop.noise_px)[0]
        problems.append(p)
    evaluate(problems, sim.simulate)
    for p in problems:
        p.refit = refit_dofs(p)
    sigs, refits, conds = signatures(problems, sim.simulate, dict(loop.method.steps))
    rows = []
    for rec, p in zip(records, problems):
        m = loop.method
        checks = {b: final_check(p, sigs[p.name], conds[p.name], refits[p.name], p.refit, sigmas[p.name],
                                 m.unexplained_alpha, m.verdict_ratio, b)["test"] for b in ("twin", "candidates")}
        rows.append({"run": rec["run"], "seed": rec["seed"], "unlisted": "+".join(rec["unlisted"]),
                     "injected": "+".join(rec["injected_effects"]), "named": "+".join(rec["named"]),
                     "exact": set(rec["named"]) == set(rec["injected_effects"]),
                     "unexplained_recorded": rec["unexplained"],
                     "unexplained_twin": checks["twin"]["unexplained"],
                     "unexplained_candidates": checks["candidates"]["unexplained"],
                     "excess_twin": round(checks["twin"]["excess_ratio"], 3),
                     "excess_candidates": round(checks["candidates"]["excess_ratio"], 3),
                     "explained_by_candidates": round(checks["twin"]["explained_by_candidates"], 3)})
    table = pd.DataFrame(rows)
    table.to_csv(out_csv, index=False)
    out = table[table.unlisted != ""]
    exact = table[(table.unlisted == "") & table.exact]
    for rule in ("recorded", "twin", "candidates"):
        col = f"unexplained_{rule}"
        print(f"{rule}: outside unexplained {int(out[col].sum())}/{len(out)}, exact in-list runs unexplained "
              f"{int(exact[col].sum())}/{len(exact)}, other in-list runs unexplained "
              f"{int(table[(table.unlisted == '') & ~table.exact][col].sum())}/{int(((table.unlisted == '') & ~table.exact).sum())}")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3:])
