"""How much of a candidate effect's marker signature lies outside E's column, per set of states: can those states tell
a thick shell (or the camera's focal scale) from a stiffer dome? A dev measurement on the starting twin; it chooses
nothing.

    python workflow/scripts/loop_shell_separation.py OUT_JSON [Hydra overrides of the loop app, e.g. loop=quick]

The signatures are the loop's own (loop.engine.signatures: each dof's final-frame marker change at its nominal step)
at the photo set's press, twist_z, twist_x and slide, and at twin-made presses at DEPTHS_MM beside them (the photo set
has one press depth). Per state set and effect dof: the column's RMS (px per nominal step), the share of its norm
outside the span of E's column (least squares), and that part's RMS: what a fit that may move E cannot absorb.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from palpation.apps.loop import loop_simulator
from palpation.io import save_json
from palpation.loop.engine import refit_dofs, signatures
from palpation.loop.problem import evaluate
from palpation.loop.real import make_problem
from palpation.loop.start import start_twin
from palpation.measured import load_measured_set
from palpation.paths import REPO_ROOT
from palpation.twin.mesh import SensorMesh

DEPTHS_MM = (1.0, 2.0, 3.0, 5.0)  # twin-made presses beside the photo set's 4 mm one
JUDGED = ("layered", "camera")  # the shell, and the camera whose focal scale also trades with E
PHOTO_STATES = ["press", "twist_z", "twist_x", "slide"]
STATE_SETS = {  # title -> the states by name (the photo set's, and the twin-made presses)
    "quick fit states (press, twist_z, twist_x)": ["press_d4", "twist_z_d4_a90", "twist_x_d2_a20"],
    "quick fit states + slide": ["press_d4", "twist_z_d4_a90", "twist_x_d2_a20", "slide_d3"],
    "slide alone": ["slide_d3"],
    "press 4 mm alone": ["press_d4"],
    "press depth series (1-5 mm)": ["press_d1", "press_d2", "press_d3", "press_d4", "press_d5"],
    "quick fit states + press depth series": ["press_d1", "press_d2", "press_d3", "press_d4", "press_d5",
                                              "twist_z_d4_a90", "twist_x_d2_a20"],
}


def outside_share(col: np.ndarray, basis: np.ndarray) -> float:
    """|col - its least-squares projection on basis's columns| / |col|."""
    rest = col - basis @ np.linalg.lstsq(basis, col, rcond=None)[0]
    return float(np.linalg.norm(rest) / np.linalg.norm(col))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("overrides", nargs="*", default=["loop=quick"])
    a = ap.parse_args(argv)
    with initialize_config_dir(version_base="1.3", config_dir=str(REPO_ROOT / "conf")):
        cfg = compose(config_name="loop", overrides=[*a.overrides, "track=false"])
    twin, loop = OmegaConf.to_object(cfg.twin), OmegaConf.to_object(cfg.loop).validate()
    _, start = start_twin(twin, loop.shell_thickness_mm * 1e-3)
    p = make_problem(load_measured_set(cfg.measured), str(cfg.measured), loop, start, holdout=[],
                     states=PHOTO_STATES, candidates=list(JUDGED))
    press = next(t for t in p.targets if t.state.kind == "press")
    p.targets += [replace(press, state=replace(press.state, name=f"press_d{d:g}", depth_mm=d)) for d in DEPTHS_MM]
    _, sim = loop_simulator(twin, loop, SensorMesh.load(cfg.mesh))
    evaluate([p], sim.simulate)
    p.refit = refit_dofs(p)  # E alone on the starting twin
    sigs, refits, _ = signatures([p], sim.simulate, dict(loop.method.steps))
    names = [t.name for t in p.targets]
    rows_per = refits[p.name].columns.shape[0] // len(names)
    out = {"overrides": a.overrides, "twin_E_pa": p.params["E"], "basis": [d.name for d in p.refit], "sets": {}}
    for title, states in STATE_SETS.items():
        ix = np.concatenate([np.arange(names.index(s) * rows_per, (names.index(s) + 1) * rows_per) for s in states])
        basis = refits[p.name].columns[ix]
        per = {}
        for sig in sigs[p.name]:
            for j, dof in enumerate(sig.dofs):
                col = sig.columns[ix, j]
                rms = float(np.sqrt(np.mean(col ** 2)))
                share = outside_share(col, basis) if rms > 0 else float("nan")
                per[f"{sig.effect}.{dof}"] = {"rms_px": round(rms, 4), "outside_E": round(share, 4),
                                              "outside_rms_px": round(share * rms, 4)}
        out["sets"][title] = {"states": states, "columns": per}
        shell = per["layered.shell_ratio"]
        print(f"{title}: shell {shell['rms_px']:.3f} px per step, {100 * shell['outside_E']:.1f} % outside E "
              f"({shell['outside_rms_px']:.3f} px); camera f {100 * per['camera.f_scale']['outside_E']:.1f} %")
    save_json(a.out, out)
    print(f"-> {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
