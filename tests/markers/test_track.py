"""Frame-to-frame tracking (SPEC §5.2, real sequences): the API the video extraction reuses."""

import numpy as np
import pytest

from palpation.camera import VIDEO_OFFSET_PX, VIDEO_SCALE
from palpation.markers.template import rest_template
from palpation.markers.track import track_sequence


def synthetic_sequence(template, n_frames=25, seed=0):
    """A slide-like drift plus a growing local bulge, 0.3 px jitter; every frame shuffled."""
    rng = np.random.default_rng(seed)
    c = template[0]
    truth, detections = [], []
    for t in range(n_frames):
        bulge = 6.0 * t / n_frames * np.exp(-np.sum((template - c) ** 2, 1) / 150.0 ** 2)[:, None]
        pos = template + np.array([1.5, 0.4]) * t + bulge * (template - c) / 100.0
        pos = pos + rng.normal(0, 0.3, pos.shape)
        truth.append(pos)
        detections.append(pos[rng.permutation(len(pos))])
    return np.array(truth), detections


def test_recovers_jitter_drop_swap_and_glare():
    tpl = rest_template()
    truth, dets = synthetic_sequence(tpl)
    # frame 5 loses marker 40 (its detection removed); frame 6 loses 40 and 41
    for t, missing in ((5, [40]), (6, [40, 41])):
        keep = ~np.isin(np.arange(127), missing)
        dets[t] = truth[t][keep][np.random.default_rng(t).permutation(keep.sum())]
    # frame 8 lists two markers in swapped rows; frame 9 has a glare point near the rim
    dets[8] = truth[8].copy()
    dets[8][[10, 11]] = dets[8][[11, 10]]
    dets[9] = np.vstack([dets[9], tpl[0] + [0.0, -370.0]])

    positions, found = track_sequence(dets, tpl, max_step_px=15.0)
    assert positions.shape == (25, 127, 2) and found.shape == (25, 127)
    assert np.all(np.isfinite(positions))
    missing = {(5, 40), (6, 40), (6, 41)}
    assert {tuple(x) for x in np.argwhere(~found)} == missing
    ok = found
    np.testing.assert_allclose(positions[ok], truth[ok])  # exact detections, exact identities
    for t, i in missing:  # filled from the neighbours' displacement: within jitter
        assert np.linalg.norm(positions[t, i] - truth[t, i]) < 1.5


def test_frame0_in_video_pixels():
    """Detections in annotation-video pixels; the template in sensor pixels (pre-alignment)."""
    tpl = rest_template()
    truth, dets = synthetic_sequence(tpl, n_frames=5)
    to_video = lambda p: p * VIDEO_SCALE + np.asarray(VIDEO_OFFSET_PX)  # noqa: E731
    positions, found = track_sequence([to_video(d) for d in dets], tpl, max_step_px=10.0)
    assert found.all()
    np.testing.assert_allclose(positions, to_video(truth))


def test_gate_rejects_jumps():
    tpl = rest_template()
    jumped = tpl.copy()
    jumped[3] += [30.0, 0.0]  # farther than max_step_px: treated as lost, filled, flagged
    positions, found = track_sequence([tpl, jumped], tpl, max_step_px=10.0)
    assert not found[1, 3] and found[1].sum() == 126
    np.testing.assert_allclose(positions[1, 3], tpl[3], atol=1e-9)


def test_bad_arguments():
    with pytest.raises(ValueError, match="no frames"):
        track_sequence([], rest_template(), 5.0)
    with pytest.raises(ValueError, match="max_step_px"):
        track_sequence([rest_template()], rest_template(), 0.0)
