"""Configs of the issue-12 apps compose and pass the key check; the slide loop's selection fails in one line."""

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from palpation.config_check import check_config
from palpation.measured_sequences import make_sequence_set
from palpation.paths import REPO_ROOT
from palpation.slides.selection import select


@pytest.mark.parametrize("app", ["silicone_sequences", "slide_loop", "twin_judge"])
def test_shipped_configs_pass(app):
    import palpation.twin.config  # noqa: F401  (registers base_twin)

    with initialize_config_dir(str(REPO_ROOT / "conf"), version_base="1.3"):
        check_config(compose(app), app)


def test_select_trials_and_frames():
    s = make_sequence_set(np.zeros((3, 5, 127, 2)), np.ones((3, 5, 127), bool), np.zeros((127, 2)),
                          np.zeros((3, 5, 3)), [], [{"name": f"t{i}"} for i in range(3)],
                          labels=np.zeros((3, 5, 127), np.int8))
    sub, numbers = select(s, [1, 3], [1, 4])
    assert numbers == [1, 3] and sub.markers.shape == (2, 3, 127, 2) and sub.labels.shape == (2, 3, 127)
    with pytest.raises(ValueError, match=r"trials \[4\] outside 1\.\.3"):
        select(s, [1, 4], None)
    with pytest.raises(ValueError, match=r"frames \[3, 9\)"):
        select(s, None, [3, 9])
