"""Reading held states from mp4 files: indexing and clear errors for bad input."""

import cv2
import numpy as np
import pytest

from palpation.realdata.video import frame_count, read_frames, read_states, state_frame_indices


@pytest.fixture(scope="module")
def tiny_video(tmp_path_factory):
    """12 flat frames whose grey level encodes the frame index (20 per frame)."""
    path = tmp_path_factory.mktemp("video") / "tiny.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10, (64, 48))
    for i in range(12):
        writer.write(np.full((48, 64, 3), 20 * i, np.uint8))
    writer.release()
    return path


def test_state_frame_indices():
    assert state_frame_indices([0, 1, 159]).tolist() == [4, 9, 799]  # annotation video: 5s + 4
    assert state_frame_indices([0, 119], offset=2).tolist() == [2, 597]  # prediction videos: 5s + 2
    with pytest.raises(ValueError, match="offset 5"):
        state_frame_indices([0], hold=5, offset=5)


def test_read_states_picks_frame_inside_hold(tiny_video):
    assert frame_count(tiny_video) == 12
    states = read_states(tiny_video)  # 12 frames = 2 complete states of 5
    assert states.shape == (2, 48, 64, 3)
    np.testing.assert_allclose(states[:, 24, 32, 0], [80, 180], atol=8)  # frames 4 and 9
    two = read_states(tiny_video, offset=2, states=[1])
    np.testing.assert_allclose(two[0, 24, 32, 0], 140, atol=8)  # frame 7


def test_read_frames_keeps_requested_order(tiny_video):
    frames = read_frames(tiny_video, [9, 0, 9])
    np.testing.assert_allclose(frames[:, 0, 0, 0], [180, 0, 180], atol=8)


def test_missing_video_names_file(tmp_path):
    path = tmp_path / "nope.mp4"
    with pytest.raises(FileNotFoundError, match="nope.mp4"):
        read_states(path)


def test_unreadable_video_names_file(tmp_path):
    path = tmp_path / "garbage.mp4"
    path.write_bytes(b"this is not an mp4 file" * 100)
    with pytest.raises(ValueError, match="garbage.mp4"):
        read_frames(path, [0])


def test_frame_out_of_range_names_file_and_range(tiny_video):
    with pytest.raises(ValueError, match=r"frame index 12 is out of range .*tiny.mp4.*12 frames"):
        read_frames(tiny_video, [0, 12])
    with pytest.raises(ValueError, match="tiny.mp4"):
        read_states(tiny_video, states=[2])  # frame 14
    with pytest.raises(ValueError, match="out of range"):
        read_frames(tiny_video, [-1])
