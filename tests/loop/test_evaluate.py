"""A recalibrated twin that diverges at a state is refused by the round, not fatal to the loop."""

import numpy as np
import pytest

from palpation.loop.inputs import Target
from palpation.loop.problem import Problem, evaluate
from palpation.loop.simulate import State


def problem() -> Problem:
    targets = [Target(State(name, "press", 2.0, 0.0), np.zeros((127, 2)), fit) for name, fit in
               (("press_d2", True), ("slide_d3", False))]
    p = Problem("real", "key", targets, {"E": 3.0e6}, ["E"])
    p.markers = np.full((2, 127, 2), 7.0)
    return p


def test_diverged_state_is_returned_and_markers_kept():
    p = problem()

    def simulate(jobs):
        return np.ones((len(jobs), 127, 2)), np.array([False, True])  # the held-out slide diverges

    assert evaluate([p], simulate, strict=False) == {"real": ["slide_d3"]}
    assert (p.markers == 7.0).all()  # the previous twin's markers stay
    with pytest.raises(ValueError, match=r"loop 'real': the current twin diverged at \['slide_d3'\]"):
        evaluate([p], simulate)
