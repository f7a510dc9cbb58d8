"""A small self-test for CI: hidden effects in twin-made sets are named, the MAE falls (coarse mesh, < 60 s)."""

import csv
import io
import os

import numpy as np
import pytest

from palpation.loop.config import LoopConfig, SearchSettings, SelftestConfig
from palpation.loop.inputs import load_targets
from palpation.loop.real import base_params
from palpation.loop.selftest import COLUMNS, confusion, rows_csv, run_selftest, summary
from palpation.loop.simulate import LoopSimulator, loop_twin_config
from palpation.markers.template import rest_template
from palpation.measured import MeasuredState, load_measured_set, make_measured_set
from palpation.twin.config import TwinConfig
from palpation.twin.mesh import cached_sensor_mesh

STATES = [MeasuredState("press_d4", "p.jpg", "press", 4.0),
          MeasuredState("twist_x_d2", "t.jpg", "twist_x", 2.0, 20.0)]


def test_small_selftest_names_the_hidden_effects(tmp_path):
    mesh = cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))
    cfg = LoopConfig(effects=["surface_contact", "camera", "mount"],
                     search=SearchSettings(n_trials=5, n_startup=3),
                     selftest=SelftestConfig(effects=["surface_contact", "camera"], runs_per_effect=1,
                                             strength_low=1.5, strength_high=2.0, states=["press", "twist_x"],
                                             holdout=["twist_x"])).validate()
    twin = loop_twin_config(TwinConfig(), cfg.shell_thickness_mm * 1e-3)
    sim = LoopSimulator(mesh, twin, rest_template())
    rest = rest_template().astype(np.float32)
    geometry_set = make_measured_set(np.stack([rest, rest]), np.ones((2, 127), bool), rest, STATES)
    template = load_targets(geometry_set, "geometry", [], cfg.selftest.states)
    geometry = {s.name: s for s in STATES}
    rows, _, _ = run_selftest(cfg, sim.simulate, base_params(twin), template, geometry, rest, tmp_path,
                              tmp_path / "study.db", "ci")
    assert [r["effect_injected"] for r in rows] == ["surface_contact", "camera"]
    # the loop only saw the files: they are valid measured sets with the states it was given
    assert load_measured_set(tmp_path / "sets" / "run_000").names == ["press_d4", "twist_x_d2"]
    assert rows[0]["effect_named"] == "surface_contact"  # a strong, unmistakable signature
    assert rows[0]["mae_after_px"] < 0.5 * rows[0]["mae_before_px"]
    assert all(r["effect_named"] in ("surface_contact", "camera", "mount", "none") for r in rows)
    table = confusion(rows, cfg.selftest.effects)
    assert sum(table["camera"].values()) == 1 and summary(rows)["runs"] == 2
    header = next(csv.reader(io.StringIO(rows_csv(rows))))
    assert tuple(header) == COLUMNS
