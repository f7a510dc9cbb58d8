"""The verdict after the final refit (loop.method): the soft-E guard (stiffness starts) and the inert-effect drop
(loop.parsimony with no re-fit). Toy marker models, no twin."""

import numpy as np
import pytest

from palpation.loop.inputs import Target
from palpation.loop.method import Method
from palpation.loop.parsimony import added_effects, prune
from palpation.loop.problem import Problem, evaluate, initial_params
from palpation.loop.refit import converge, stiffness_starts
from palpation.loop.simulate import State
from palpation.markers.template import rest_template

E_TRUE = 1.0e6
REST = rest_template().astype(np.float64)
FIELD = np.random.default_rng(5).normal(size=REST.shape)
NOISE = 0.05


def soft_basin(state: State, p) -> np.ndarray:
    """Misfit g(u) x a field, u = log2(E / E_TRUE): zero at the truth, and a narrow false well at u = -2 (E four
    times too soft, g = 0.1) that LM from inside it never leaves."""
    u = np.log2(p["E"] / E_TRUE)
    g = (1.0 - np.exp(-u ** 2 / 0.5)) - 0.9 * np.exp(-(u + 2.0) ** 2 / 0.05)
    return REST + {"a": 10.0, "h": 12.0}[state.name] * g * FIELD


def simulate(jobs):
    return np.stack([soft_basin(s, p) for s, p in jobs]), np.zeros(len(jobs), bool)


def soft_problem() -> Problem:
    rng = np.random.default_rng(1)
    truth = initial_params({"E": E_TRUE})
    targets = [Target(State(n, "press", 2.0), soft_basin(State(n, "press"), truth) + rng.normal(0, NOISE, REST.shape),
                      n == "a") for n in ("a", "h")]
    p = Problem("soft", "k", targets, initial_params({"E": E_TRUE / 4}), ["E"], noise_px=NOISE)
    evaluate([p], simulate)
    return p


@pytest.mark.parametrize("factors", [(), (2.0, 0.5)])
def test_the_stiffness_starts_leave_the_soft_basin(factors):
    p = soft_problem()
    log = converge([p], simulate, None, 10, 2.0, stiffness=factors)["soft"]
    found = abs(np.log2(p.params["E"] / E_TRUE)) < 0.05
    assert found == bool(factors) and log["stiff"] == int(bool(factors))
    assert (log["after"]["fit"] < 2 * NOISE) == bool(factors)


def test_stiffness_starts_scale_contact_with_the_sensor_and_stay_in_the_box():
    p = Problem("c", "k", [], initial_params({"E": 1.0e6, "k_s": 2000.0}), ["E", "k_s", "cam_f_scale"])
    starts = stiffness_starts(p, (2.0, 0.5), {"E": (1.0e5, 1.5e6)})
    assert [s["E"] for s in starts] == [1.5e6, 5.0e5] and [s["k_s"] for s in starts] == [4000.0, 1000.0]
    assert all(s["cam_f_scale"] == p.params["cam_f_scale"] for s in starts)
    assert stiffness_starts(Problem("n", "k", [], initial_params({}), ["cam_f_scale"]), (2.0,), None) == []


def anchored(state: State, p) -> np.ndarray:
    """Markers that respond to E and, where `live`, to the marker anchor."""
    return REST + {"a": 3.0, "h": 4.0}[state.name] * np.log(p["E"] / E_TRUE) * FIELD + \
        (5.0 * p["marker_anchor"] * FIELD[::-1] if LIVE[0] else 0.0)


LIVE = [True]


@pytest.mark.parametrize("live", [True, False])
def test_an_inert_added_effect_leaves_the_named_set(live):
    LIVE[0] = live
    try:
        rng = np.random.default_rng(3)
        truth = initial_params({"E": E_TRUE, "marker_anchor": 0.8 if live else 0.0})
        targets = [Target(State(n, "press", 2.0), anchored(State(n, "press"), truth) +
                          rng.normal(0, NOISE, REST.shape), n == "a") for n in ("a", "h")]
        p = Problem("m", "k", targets, {**truth}, ["E", "marker_anchor"], effects=["marker_anchor"], noise_px=NOISE)
        p.rounds = [{"round": 1, "accepted": True, "effects": ["marker_anchor"]}]
        sim = lambda jobs: (np.stack([anchored(s, q) for s, q in jobs]), np.zeros(len(jobs), bool))  # noqa: E731
        evaluate([p], sim)
        prune([p], sim, {"m": None}, 0, Method().gate_z)  # iters 0: the switch-off test alone ("inert")
        assert (added_effects(p) == ["marker_anchor"]) == live
        assert p.parsimony["dropped"] == ([] if live else ["marker_anchor"])
    finally:
        LIVE[0] = True
