"""Bad measured input reaches the loop's entry points as one clear error, before anything is simulated."""

import dataclasses

import numpy as np
import pytest

from palpation.loop.config import LoopConfig
from palpation.loop.inputs import load_targets
from palpation.loop.real import make_problem
from palpation.markers.template import rest_template
from palpation.measured import MeasuredState, make_measured_set

STATES = [MeasuredState("rest", "r.png", "rest", 0.0), MeasuredState("p4", "p.png", "press", 4.0),
          MeasuredState("tx", "t.png", "twist_x", 2.0, 20.0), MeasuredState("sl", "s.png", "slide", 3.0)]


def measured(markers=None, states=STATES):
    rest = rest_template().astype(np.float32)
    m = np.stack([rest] * len(states)) if markers is None else markers
    return make_measured_set(m, np.ones(m.shape[:2], bool), rest, states)


def test_good_set_gives_fit_and_held_out_targets():
    targets = load_targets(measured(), "mine", holdout=["slide"])
    assert [(t.name, t.fit) for t in targets] == [("p4", True), ("tx", True), ("sl", False)]
    assert load_targets(measured(), "mine", states=["press", "tx"])[1].state.angle_deg == 20.0


@pytest.mark.parametrize("mset, match", [
    (lambda: dataclasses.replace(measured(), markers=np.zeros((4, 120, 2), np.float32)),
     r"shape \(4, 120, 2\).*127"),
    (lambda: dataclasses.replace(measured(), markers=np.full((4, 127, 2), np.nan, np.float32)),
     r"NaN/inf.*\['p4', 'rest', 'sl', 'tx'\]"),
    (lambda: dataclasses.replace(measured(), states=[*STATES[:3], MeasuredState("x", "x", "poke", 1.0)]),
     "unknown trajectory kind 'poke'"),
    (lambda: measured(states=STATES[:1]), "no interaction state"),
])
def test_bad_sets_fail_clearly(mset, match):
    with pytest.raises(ValueError, match=match):
        load_targets(mset(), "mine.npz")


@pytest.mark.parametrize("kwargs, match", [
    (dict(holdout=["twist_z"]), "'twist_z' is neither a state name nor a trajectory kind of mine"),
    (dict(holdout=["p4", "tx", "slide"]), "leaves no state of mine to fit"),
    (dict(states=["nope"]), "loop.states"),
    (dict(twist_z_angle="ninety"), "twist_z_angle"),
])
def test_bad_loop_choices_fail_clearly(kwargs, match):
    with pytest.raises(ValueError, match=match):
        load_targets(measured(), "mine", **kwargs)


def test_problem_checks_config_names():
    with pytest.raises(ValueError, match="unknown effect"):
        make_problem(measured(), "mine", LoopConfig(effects=["gravity"]).validate(), {})
