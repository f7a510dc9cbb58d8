"""A tiny self-test for CI (the size is a config knob): an in-list effect is named, an out-of-list one is
reported unexplained, the CSV has the issue-13 columns (coarse mesh)."""

import csv
import io
import os

import numpy as np
import pytest

from palpation.loop.config import LoopConfig, SearchSettings, SelftestConfig
from palpation.loop.inputs import load_targets
from palpation.loop.method import Method
from palpation.loop.real import base_params
from palpation.loop.selftest.fixed import COLUMNS, confusion, rows_csv, run_selftest, summary
from palpation.loop.selftest_config import parse_case
from palpation.loop.simulate import LoopSimulator, loop_twin_config
from palpation.loop.unlisted import UNLISTED
from palpation.markers.template import rest_template
from palpation.measured import MeasuredState, load_measured_set, make_measured_set
from palpation.twin.config import TwinConfig
from palpation.twin.mesh import cached_sensor_mesh

STATES = [MeasuredState("press_d4", "p.jpg", "press", 4.0),
          MeasuredState("twist_x_d2", "t.jpg", "twist_x", 2.0, 20.0)]


def test_cases_parse_and_dependencies_are_enforced():
    assert parse_case("surface_contact+friction", []) == (["surface_contact", "friction"], [])
    assert parse_case("camera+unlisted:image_distortion", []) == (["camera"], ["image_distortion"])
    with pytest.raises(ValueError, match="friction acts only through.*surface_contact\\+friction"):
        parse_case("friction", [])
    assert parse_case("friction", ["surface_contact"]) == (["friction"], [])
    with pytest.raises(ValueError, match="unknown effect"):
        parse_case("unlisted:gravity", [])


def test_unlisted_effects_move_markers_outside_the_candidates():
    rest = rest_template().astype(np.float64)
    pressed = (rest + 0.05 * (rest - rest.mean(axis=0)))[None]  # displaced: the physical kinds act on displacements
    rng = np.random.default_rng(0)
    for name, f in UNLISTED.items():
        moved = f(pressed.copy(), 1.0, rng, rest)
        assert moved.shape == pressed.shape and np.abs(moved - pressed).max() > 1.5, name


def test_tiny_selftest_names_in_list_and_flags_out_of_list(tmp_path):
    mesh = cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))
    cfg = LoopConfig(effects=["surface_contact", "camera"], search=SearchSettings(n_trials=5, n_startup=3), selftest=SelftestConfig(cases=["surface_contact", "unlisted:marker_defect"], runs_per_case=1,
                                             strength_low=1.5, strength_high=2.0, states=["press", "twist_x"],
                                             holdout=["twist_x"]), method=Method(pair_tries=0)).validate()
    twin = loop_twin_config(TwinConfig(), cfg.shell_thickness_mm * 1e-3)
    sim = LoopSimulator(mesh, twin, rest_template())
    rest = rest_template().astype(np.float32)
    geometry_set = make_measured_set(np.stack([rest, rest]), np.ones((2, 127), bool), rest, STATES)
    template = load_targets(geometry_set, "geometry", [], cfg.selftest.states)
    geometry = {s.name: s for s in STATES}
    rows, _, _ = run_selftest(cfg, sim.simulate, base_params(twin), template, geometry, rest, tmp_path,
                              tmp_path / "study.journal", "ci")
    assert [r["effects_injected"] for r in rows] == ["surface_contact", "unlisted:marker_defect"]
    # the loop only saw the files: they are valid measured sets with the states it was given
    assert load_measured_set(tmp_path / "sets" / "run_000").names == ["press_d4", "twist_x_d2"]
    assert rows[0]["effects_named"] == "surface_contact"  # a strong, unmistakable signature, not unexplained
    assert rows[0]["mae_after_px"] < 0.5 * rows[0]["mae_before_px"]
    assert rows[1]["unexplained"] and rows[1]["effects_named"].endswith("unexplained")
    s = summary(rows)
    assert s["runs"] == 2 and s["exact_named"] == 1.0 and s["out_of_list_unexplained"] == 1.0
    table = confusion(rows, cfg.effects)
    assert table["unexplained"]["unlisted"] == 1 and table["surface_contact"]["surface_contact"] == 1
    header = next(csv.reader(io.StringIO(rows_csv(rows))))
    assert tuple(header) == COLUMNS and "effects_injected" in header and "effects_named" in header
