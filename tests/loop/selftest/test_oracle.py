"""The identifiability oracle (loop.selftest.oracle) on the coarse twin, cases whose answer is known: a camera moved
two nominal steps is needed by its data, one moved a thousandth of a step is not, and an outside run is not judged."""

import os

import numpy as np

from palpation.loop.config import LoopConfig, SelftestConfig
from palpation.loop.inputs import load_targets
from palpation.loop.method import Method
from palpation.loop.real import base_params
from palpation.loop.selftest.fixed import Injection, base_for, make_sets, simulate_injections, switch_on
from palpation.loop.selftest.oracle import identifiable
from palpation.loop.simulate import LoopSimulator, loop_twin_config
from palpation.markers.template import rest_template
from palpation.measured import MeasuredState, make_measured_set
from palpation.twin.config import TwinConfig
from palpation.twin.mesh import cached_sensor_mesh

STATES = [MeasuredState("press_d4", "p.jpg", "press", 4.0),
          MeasuredState("twist_x_d2", "t.jpg", "twist_x", 2.0, 20.0)]


def _camera_run(cfg, base, run: int, strength: float, unlisted=()) -> Injection:
    rng = np.random.default_rng([7, run])
    on, params = base_for(["camera"], cfg, base)
    betas: dict[str, float] = {}
    params = switch_on(params, "camera", strength, rng, dict(cfg.method.steps), betas)
    return Injection(run, ["camera"], list(unlisted), {"camera": strength, **{u: 1.0 for u in unlisted}}, betas, on,
                     params, tag=f"dev_seed7_run{run}", rng=rng)


def test_oracle_keeps_what_the_data_need_and_drops_what_they_cannot_show(tmp_path):
    mesh = cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))
    cfg = LoopConfig(effects=["camera", "marker_anchor"], max_frames=30,
                     selftest=SelftestConfig(states=["press", "twist_x"], holdout=["twist_x"]),
                     method=Method(final_refit_iters=2)).validate()
    twin = loop_twin_config(TwinConfig(), cfg.shell_thickness_mm * 1e-3)
    sim = LoopSimulator(mesh, twin, rest_template(), max_frames=cfg.max_frames)
    rest = rest_template().astype(np.float32)
    template = load_targets(make_measured_set(np.stack([rest, rest]), np.ones((2, 127), bool), rest, STATES),
                            "geometry", [], cfg.selftest.states)
    base = base_params(twin)
    runs = [_camera_run(cfg, base, 0, 2.0), _camera_run(cfg, base, 1, 1e-3),
            _camera_run(cfg, base, 2, 2.0, unlisted=["marker_defect"])]
    markers = simulate_injections(runs, template, sim.simulate, cfg, base, None)
    paths = make_sets(runs, markers, template, 0.2, None, tmp_path / "sets", {s.name: s for s in STATES}, rest)
    out = identifiable(cfg, runs, paths, sim.simulate, base)
    assert set(out) == {"dev_seed7_run0", "dev_seed7_run1"}  # the outside run is not judged
    strong, hidden = out["dev_seed7_run0"], out["dev_seed7_run1"]
    assert strong["identifiable"] == ["camera"] and strong["tests"]["camera"]["z_off"] > cfg.method.gate_z
    assert strong["tests"]["camera"]["z_refit"] > cfg.method.gate_z  # E re-fitted from the truth cannot take it
    assert hidden["identifiable"] == [] and abs(hidden["tests"]["camera"]["z_off"]) <= cfg.method.gate_z
