"""The measured-sequence format (issue 12): round trip and one-line errors naming the file and the fix."""

import json

import numpy as np
import pytest

from palpation.io import save_npz
from palpation.mapping.photo import PHOTO_SIZE
from palpation.mapping.silicone_sequences import centreline, phantom_vessels, photo_to_world, silicone_sequences
from palpation.measured_sequences import load_sequence_set, make_sequence_set, save_sequence_set


def toy(t=2, f=3, labels=True):
    rng = np.random.default_rng(0)
    rest = rng.uniform(500, 1400, (127, 2))
    markers = rest + rng.normal(0, 2, (t, f, 127, 2))
    pose = np.zeros((t, f, 3))
    pose[..., 1] = np.arange(f) * 3.8
    pose[..., 2] = 3.0
    lines = [np.array([[-10.0, 5.0], [10.0, 6.0]]), np.array([[-10.0, -5.0], [0.0, -4.0], [10.0, -6.0]])]
    lab = (rng.uniform(size=(t, f, 127)) < 0.1).astype(np.int8) if labels else None
    return make_sequence_set(markers, np.ones((t, f, 127), bool), rest, pose, lines,
                             [{"name": f"trial_{i}"} for i in range(t)], [4.0, None], labels=lab)


def test_round_trip(tmp_path):
    s = toy()
    save_sequence_set(tmp_path / "seq", s)
    back = load_sequence_set(tmp_path / "seq.npz")
    np.testing.assert_array_equal(back.markers, s.markers)
    np.testing.assert_array_equal(back.pose_mm, s.pose_mm)
    np.testing.assert_array_equal(back.labels, s.labels)
    assert [len(c) for c in back.centrelines()] == [2, 3]
    assert back.vessels[0]["diameter_mm"] == 4.0 and back.vessels[1]["diameter_mm"] is None
    assert back.subset([1]).trials == [{"name": "trial_1"}]
    save_sequence_set(tmp_path / "nolab", toy(labels=False))
    assert load_sequence_set(tmp_path / "nolab").labels is None


def test_frames_vs_poses_mismatch(tmp_path):
    s = toy()
    s.pose_mm = s.pose_mm[:, :2]
    with pytest.raises(ValueError, match=r"seq\.npz: pose_mm has 2 trials x 2 frames but markers has 2 x 3"):
        save_sequence_set(tmp_path / "seq", s)
    assert not (tmp_path / "seq.npz").exists()


def test_missing_vessel_geometry_names_the_file(tmp_path):
    save_sequence_set(tmp_path / "seq", toy())
    with np.load(tmp_path / "seq.npz") as z:
        arrays = {k: z[k] for k in z.files if k not in ("vessel_points_mm", "vessel_id")}
    save_npz(tmp_path / "seq.npz", **arrays)
    with pytest.raises(ValueError) as exc:
        load_sequence_set(tmp_path / "seq")
    msg = str(exc.value)
    assert "seq.npz: no vessel geometry" in msg and "\n" not in msg and "empty" in msg


def test_bad_vessel_table_and_version(tmp_path):
    save_sequence_set(tmp_path / "seq", toy())
    meta = json.loads((tmp_path / "seq.json").read_text())
    meta["vessels"] = meta["vessels"][:1]
    (tmp_path / "seq.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"seq\.json: vessel_id runs 0\.\.1 but 'vessels' lists 1"):
        load_sequence_set(tmp_path / "seq")
    meta["format_version"] = 9
    (tmp_path / "seq.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="format_version 9 is not supported"):
        load_sequence_set(tmp_path / "seq")


def test_vessel_free_scene_is_allowed(tmp_path):
    s = make_sequence_set(np.zeros((1, 2, 127, 2)), np.ones((1, 2, 127), bool), np.zeros((127, 2)),
                          np.zeros((1, 2, 3)), [], [{"name": "free"}])
    save_sequence_set(tmp_path / "free", s)
    assert load_sequence_set(tmp_path / "free").centrelines() == []


def test_photo_to_world_corners_and_centreline():
    corners = photo_to_world(np.array([[0.0, 0.0], [PHOTO_SIZE[0], PHOTO_SIZE[1]]]))
    np.testing.assert_allclose(corners, [[-245.0, -54.0], [-425.0, 46.0]])
    # a 40 x 5 mm bar along x at y = 2: centreline on y = 2, diameter 5
    xx, yy = np.meshgrid(np.arange(-20, 20, 0.1) + 0.05, np.arange(-0.5 * 5, 0.5 * 5, 0.1) + 0.05)
    line, d = centreline(np.stack([xx.ravel(), yy.ravel() + 2.0], 1), 4.0, 0.01)
    np.testing.assert_allclose(line[:, 1], 2.0, atol=1e-9)
    assert abs(d - 5.0) < 0.05 and np.ptp(line[:, 0]) > 35


def test_phantom_vessels_and_silicone_sequences(tmp_path):
    lines, diameters = phantom_vessels()
    assert len(lines) == 4 and all(3.0 < d < 6.0 for d in diameters)  # SPEC §13.6: radius ~2 mm
    for line in lines:  # inside the workspace
        assert (line[:, 0] >= -425).all() and (line[:, 0] <= -245).all() and (np.abs(line[:, 1] - -4) <= 50).all()
    rng = np.random.default_rng(1)
    data = {"markers": rng.uniform(0, 1000, (2, 4, 127, 2)).astype(np.float32), "found": np.ones((2, 4, 127), bool),
            "labels": np.zeros((2, 4, 127), np.int8), "videos": np.array([1, 10])}
    s = silicone_sequences(data, np.zeros((127, 2)))
    assert s.pose_mm.shape == (2, 4, 3) and (s.pose_mm[..., 2] == 3.0).all()
    assert np.diff(s.pose_mm[0, :, 1]).max() < 0 < np.diff(s.pose_mm[1, :, 1]).min()  # two directions
    save_sequence_set(tmp_path / "sil", s)
    assert load_sequence_set(tmp_path / "sil").trials[1]["video"] == 10
