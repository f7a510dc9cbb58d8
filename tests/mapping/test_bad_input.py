"""Bad input fails early with one line naming the input and the fix."""

import dataclasses

import numpy as np
import pytest

from palpation.mapping.grid import silicone_grid
from palpation.mapping.pipeline import MapSettings, build_stack, config_maps
from palpation.mapping.samples import Samples
from palpation.mapping.sources import MapSource, sim_source


def test_poses_and_markers_of_different_lengths(sim_set):
    s = sim_source(sim_set, "test")
    with pytest.raises(ValueError, match="144 frames of markers but 143 poses"):
        dataclasses.replace(s, poses=[p[:-1] for p in s.poses])


def test_pose_in_the_wrong_unit_exceeds_the_grid_limit(sim_set, make_scores):
    s = sim_source(sim_set, "test")
    in_mm = [p.copy() for p in s.poses]
    for p in in_mm:
        p[:, :3, 3] *= 1000.0  # T_BA written in mm instead of metres
    bad = dataclasses.replace(s, poses=in_mm)
    with pytest.raises(ValueError, match="pose units"):
        config_maps("A-to-A", bad, **make_scores(sim_set))


def test_stack_over_max_grid_px(sim_set, make_scores):
    with pytest.raises(ValueError, match="max_grid_px"):
        config_maps("A-to-A", sim_source(sim_set, "test"), **make_scores(sim_set),
                    settings=MapSettings(max_grid_px=1000))


def test_empty_prediction_set(sim_set):
    with pytest.raises(ValueError, match="empty prediction set"):
        config_maps("A-to-A", sim_source(sim_set, "test"), np.zeros(0, np.float32), np.zeros(0, np.int8),
                    np.zeros(0, np.int64), np.zeros(0, np.int64))
    empty = Samples(*(np.zeros((0,) + sh) for sh in ((), (), (127, 2), (127,), (127,))))
    src = MapSource("silicone", [], [], None, [], 1, np.zeros(0, int), ["silicone"], {})
    with pytest.raises(ValueError, match="empty prediction set"):
        build_stack(src, empty, MapSettings(), "A-to-B (silicone)")


def test_scores_of_another_clip_len_map_their_own_frames(sim_set, make_scores):
    """The ids travel with the scores: an L = 3 run maps its own central frames, no window rule here."""
    res = config_maps("A-to-A", sim_source(sim_set, "test"), **make_scores(sim_set, clip_len=3))
    assert res.n_samples == len(make_scores(sim_set, clip_len=3)["frame"])


def test_scores_whose_ids_do_not_fit_the_test_set(sim_set, make_scores):
    scores = make_scores(sim_set)
    with pytest.raises(ValueError, match="outside the 3 test sequences"):
        config_maps("A-to-A", sim_source(sim_set, "test"), **{**scores, "frame": scores["frame"] + 1000})
    with pytest.raises(ValueError, match="labels differ"):
        config_maps("A-to-A", sim_source(sim_set, "test"), **{**scores, "labels": 1 - scores["labels"]})


def test_missing_inputs_name_the_rule(tmp_path):
    from palpation.mapping.sources import meat_source, silicone_source

    with pytest.raises(FileNotFoundError, match="silicone_set"):
        silicone_source(tmp_path / "silicone.npz")
    with pytest.raises(FileNotFoundError, match="meat_set"):
        meat_source(tmp_path / "meat.npz")
    assert silicone_grid().n_px == 18000
