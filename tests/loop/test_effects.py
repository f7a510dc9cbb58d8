"""Candidate effects: steps, bounds, the split into twin settings, the final twin as Hydra overrides."""

import numpy as np
import pytest

from palpation.loop.effects import EFFECTS, PARAMS, clip, defaults, move, split, strength, twin_overrides
from palpation.loop.problem import initial_params


def test_every_effect_names_known_parameters_and_steps():
    for e in EFFECTS.values():
        assert e.dofs and set(e.params) <= set(PARAMS)
        for d in e.dofs:
            assert {name for name, _, _ in d.moves} <= set(e.params)
    assert defaults(["surface_contact", "layered"]) == {"k_s": 0.0, "shell_ratio": 1.0}


def test_move_add_and_mul_and_clip():
    p = initial_params({"E": 1e6})
    assert move(p, EFFECTS["surface_contact"].dofs[0], 1.5)["k_s"] == pytest.approx(3e3)
    assert move(p, EFFECTS["viscous"].dofs[0], -1.0)["alpha"] == pytest.approx(0.004)
    assert move(p, EFFECTS["camera"].dofs[1], 2.0, {"cam_rotation_deg": 1.0})["cam_rotation_deg"] == 2.0
    assert clip({"k_s": 1e9, "mu": -1.0, "cam_dx_px": 3.0}) == {"k_s": 3e4, "mu": 0.0, "cam_dx_px": 3.0}


def test_split_and_overrides_carry_units_and_switches():
    params = {"E": 9e5, "k_s": 1e3, "mount_dz_mm": 0.5, "cam_f_scale": 1.02, "shell_ratio": 2.0,
              "marker_anchor": 1.0}
    env, camera, mount, markers = split(params)
    assert env == {"E": 9e5, "k_s": 1e3, "shell_ratio": 2.0}
    assert camera == {"f_scale": 1.02} and mount == {"dz": pytest.approx(5e-4)} and markers == {"anchor": 1.0}
    out = twin_overrides(params, ["surface_contact", "camera", "mount", "layered", "marker_anchor"], 1.5e-3)
    assert out["contact"] == {"k_s": 1e3, "phantom_contact": True}
    assert out["material"] == {"E": 9e5, "shell_ratio": 2.0, "shell_thickness": 1.5e-3}
    assert out["mount"] == {"dz": pytest.approx(5e-4)} and out["camera"] == {"f_scale": 1.02}
    assert out["markers"] == {"anchor": 1.0}
    with pytest.raises(ValueError, match="unknown loop parameter 'young'"):
        split({"young": 1.0})
    assert np.isfinite(list(initial_params({}).values())).all()


@pytest.mark.parametrize("effect", sorted(EFFECTS))
def test_strength_reads_back_the_steps_an_effect_was_moved(effect):
    off = initial_params({})
    assert strength(effect, off) == 0.0
    params = dict(off)
    for dof, beta in zip(EFFECTS[effect].dofs, (0.6, -0.8, 0.5, 0.3)):
        params = move(params, dof, abs(beta) if dof.nonneg else beta)
    betas = [abs(b) for b in (0.6, -0.8, 0.5, 0.3)[:len(EFFECTS[effect].dofs)]]
    assert strength(effect, params) == pytest.approx(np.sqrt(sum(b * b for b in betas)))
