"""workflow/scripts/loop_shell_separation.py: the share of a column outside E's, and state sets it can build."""

import importlib.util

import numpy as np
import pytest

from palpation.paths import REPO_ROOT

SPEC = importlib.util.spec_from_file_location("loop_shell_separation",
                                              REPO_ROOT / "workflow" / "scripts" / "loop_shell_separation.py")
sep = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(sep)


def test_outside_share_is_the_sine_of_the_angle_to_the_basis():
    rng = np.random.default_rng(0)
    e = rng.normal(size=(200, 1))
    other = rng.normal(size=200)
    other -= e[:, 0] * (e[:, 0] @ other) / (e[:, 0] @ e[:, 0])  # orthogonal to E's column
    assert sep.outside_share(3.0 * e[:, 0], e) == pytest.approx(0.0, abs=1e-12)
    assert sep.outside_share(other, e) == pytest.approx(1.0)
    col = e[:, 0] / np.linalg.norm(e) + other / np.linalg.norm(other)  # 45 degrees
    assert sep.outside_share(col, e) == pytest.approx(np.sqrt(0.5))


def test_every_state_set_names_a_state_the_script_makes():
    photo = {"press_d4", "twist_z_d4_a90", "twist_x_d2_a20", "slide_d3"}
    made = {f"press_d{d:g}" for d in sep.DEPTHS_MM}
    for title, states in sep.STATE_SETS.items():
        assert states and set(states) <= photo | made, title
