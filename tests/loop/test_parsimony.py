"""Parsimony in the verdict (loop.parsimony) on a toy marker model: an inert effect, one whose part another
effect can take over, and one the data need."""

import numpy as np

from palpation.loop.effects import EFFECTS
from palpation.loop.inputs import Target
from palpation.loop.parsimony import added_effects, prune, removal_set
from palpation.loop.problem import Problem, evaluate, initial_params
from palpation.loop.report import verdict_lines
from palpation.loop.simulate import State
from palpation.markers.template import rest_template

REST = rest_template().astype(np.float64)
Q = (REST - REST.mean(axis=0)) / 100.0  # radial
G = np.random.default_rng(3).normal(size=REST.shape)
AMP = {"a": 3.0, "b": 2.0, "h": 2.5}


def toy(state: State, p) -> np.ndarray:
    """Markers: a camera shift (dx), a mount tilt (the same field as the layered shell here: the two trade),
    the shell ratio (x G) and a tiny viscous term."""
    a = AMP[state.name]
    return (REST + np.array([p["cam_dx_px"], 0.0]) + a * (p["mount_tilt_x_deg"] / 2.0) * G
            + a * (p["shell_ratio"] - 1.0) * G + a * 50.0 * (p["alpha"] - 0.02) * Q)


def simulate(jobs):
    return np.stack([toy(s, p) for s, p in jobs]), np.zeros(len(jobs), bool)


def problem(truth, final, effects) -> Problem:
    rng = np.random.default_rng(0)
    truth = initial_params(truth)
    targets = [Target(State(n, "press", 2.0), toy(State(n, "press"), truth) + rng.normal(0, 0.1, REST.shape),
                      n != "h") for n in AMP]
    searched = [n for e in effects for n in EFFECTS[e].params]  # the effects' parameters, as the rounds leave them
    p = Problem("toy", "k", targets, initial_params(final), searched, effects=list(effects))
    p.rounds = [{"round": k + 1, "accepted": True, "effects": [e]} for k, e in enumerate(effects)]
    evaluate([p], simulate)
    return p


def test_an_inert_effect_leaves_the_named_set_and_the_twin():
    # the viscous alpha came back to 0.0201 (its off value 0.02): taking it out changes nothing
    p = problem({"cam_dx_px": 5.0}, {"cam_dx_px": 5.0, "alpha": 0.0201}, ["camera", "viscous"])
    prune([p], simulate, {"toy": None}, iters=5, z_crit=2.0)
    assert p.effects == ["camera"] and added_effects(p) == ["camera"] and p.parsimony["dropped"] == ["viscous"]
    assert p.params["alpha"] == 0.02 and "alpha" not in p.searched
    assert p.parsimony["passes"][0]["viscous"]["z_refit"] is None  # settled without a refit
    assert p.parsimony["passes"][-1]["camera"]["needed"]


def test_an_effect_whose_part_the_rest_takes_over_after_a_refit_goes():
    # the data hold a mount tilt of 2 steps; the final twin split it between the mount and the shell ratio (the same
    # field here): without the shell, the mount re-fitted alone reaches the data again
    p = problem({"mount_tilt_x_deg": 4.0}, {"mount_tilt_x_deg": 2.0, "shell_ratio": 2.0}, ["mount", "layered"])
    prune([p], simulate, {"toy": None}, iters=8, z_crit=2.0)
    first = p.parsimony["passes"][0]
    assert first["layered"]["z_off"] > 2.0 and first["layered"]["z_refit"] is not None  # needed until re-fitted
    assert len(p.parsimony["dropped"]) == 1 and len(p.effects) == 1  # one of the two goes, the other stays
    kept = p.effects[0]
    assert abs(p.params["mount_tilt_x_deg"] / 2.0 + p.params["shell_ratio"] - 1.0 - 2.0) < 0.05
    assert p.parsimony["passes"][-1][kept]["needed"]


def test_effects_the_data_need_all_stay():
    p = problem({"cam_dx_px": 5.0, "mount_tilt_x_deg": 3.0}, {"cam_dx_px": 5.0, "mount_tilt_x_deg": 3.0},
                ["camera", "mount"])
    prune([p], simulate, {"toy": None}, iters=5, z_crit=2.0)
    assert p.effects == ["camera", "mount"] and p.parsimony["dropped"] == []


def test_taking_out_contact_takes_out_friction_with_it():
    p = Problem("t", "k", [], initial_params({}), [], effects=["surface_contact", "friction", "camera"])
    assert removal_set(p, "surface_contact") == ["surface_contact", "friction"]
    assert removal_set(p, "camera") == ["camera"]


def test_a_negligible_effect_goes_before_any_test():
    # a 0.05-step mount tilt (0.1 deg of a 2-deg step): the data hold it (a strong toy field, noise 0.1 px), so the
    # removal test alone would keep it; below the floor of 0.1 nominal steps it goes untested
    truth = {"cam_dx_px": 5.0, "mount_tilt_x_deg": 0.1}
    AMP.update(a=300.0, b=200.0, h=250.0)
    try:
        tested = problem(truth, truth, ["camera", "mount"])
        prune([tested], simulate, {"toy": None}, iters=0, z_crit=2.0)
        assert tested.effects == ["camera", "mount"]  # significant at this noise
        floored = problem(truth, truth, ["camera", "mount"])
        prune([floored], simulate, {"toy": None}, iters=0, z_crit=2.0, min_steps=0.1)
    finally:
        AMP.update(a=3.0, b=2.0, h=2.5)
    assert floored.effects == ["camera"] and floored.parsimony["negligible"] == ["mount"]
    assert floored.params["mount_tilt_x_deg"] == 0.0 and floored.markers is not None
    assert "mount" not in floored.parsimony["passes"][0]  # never tested
    floored.rounds = [{**r, "effect": r["effects"][0], "after": {"gate": {"why": "toy"}}} for r in floored.rounds]
    text = "\n".join(verdict_lines(floored, {"mean_px": 0.5, "target_mm": 0.25, "target_set": "toy"}))
    assert "negligible (closer to off than loop.method.min_strength_steps nominal steps): mount;" in text
    assert "not significantly needed" not in text  # the report says why it went
