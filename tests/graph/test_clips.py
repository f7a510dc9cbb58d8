import numpy as np
import pytest

from palpation.graph.augment import rotate_points, rotation_permutations, sim_labels
from palpation.graph.clips import ClipSet, window_starts
from palpation.graph.layout import rest_layout
from palpation.graph.sources import Sequences, split_sorted


def test_window_counts():
    assert np.array_equal(window_starts(317, 5, 24), np.arange(9) * 24)  # 9 per trajectory, starts 0..192
    assert len(window_starts(317, 7, 24)) == 7 and len(window_starts(317, 1, 24)) == 13
    assert len(window_starts(16, 5, 1)) == 12  # Silicone: 12 per 16-frame video
    assert len(window_starts(16, 7, 1)) == 10  # 160 - 10(L-1) central frames over 10 videos


@pytest.mark.parametrize("clip_len", [1, 5, 7])
def test_centred_windows_cover_every_frame(clip_len):
    """Meat holds only central frames: one window per frame, ends replicated (219 at any L)."""
    rest = rest_layout("ideal")
    markers = [np.broadcast_to(rest, (n, 127, 2)).astype(np.float32) + np.arange(n)[:, None, None]
               for n in (22,) * 9 + (21,)]
    seqs = Sequences("meat", list(range(10)), markers, 1, labels=[np.zeros(m.shape[:2], np.int8) for m in markers],
                     window="centred")
    clips = ClipSet(seqs, clip_len, rest)
    assert len(clips) == 219
    m, _ = clips.gather([0, 21])  # first and last frame of trial 1
    shift = m[:, :, 0, 0] - rest[0, 0]  # frame index encoded as an offset
    half = clip_len // 2
    assert np.allclose(shift[0], np.clip(np.arange(clip_len) - half, 0, 21))
    assert np.allclose(shift[1], np.clip(21 + np.arange(clip_len) - half, 0, 21))


def _clips(lengths, clip_len, stride, window="full"):
    rest = rest_layout("ideal")
    markers = [np.zeros((n, 127, 2), np.float32) for n in lengths]
    seqs = Sequences("s", list(range(len(lengths))), markers, stride,
                     labels=[np.zeros((n, 127), np.int8) for n in lengths], window=window)
    return ClipSet(seqs, clip_len, rest)


def test_central_frames():
    """Each window's prediction is for frame start + d (L // 2): the ids stored with the scores."""
    seq, frame = _clips([16] * 10, 5, 1).central_frames()  # Silicone: frames 2..13 of each video
    assert len(seq) == 120 and frame[:12].tolist() == list(range(2, 14)) and (seq[:12] == 0).all() and seq[-1] == 9
    seq, frame = _clips([22, 21], 5, 1, "centred").central_frames()  # Meat: every stored frame
    assert len(seq) == 22 + 21 and frame.tolist() == list(range(22)) + list(range(21))
    seq, frame = _clips([317], 5, 24).central_frames()  # Sim: 9 windows, starts 0..192
    assert frame.tolist() == [48, 72, 96, 120, 144, 168, 192, 216, 240]
    assert _clips([317], 4, 24).central_frames()[1][0] == 48  # even L: k = 2 of frames 0, 24, 48, 72


def test_split_350_75_75():
    ids = [f"trajectory_{i:04d}" for i in range(500)][::-1]
    parts = [split_sorted(ids, s) for s in ("train", "val", "test")]
    assert [len(p) for p in parts] == [350, 75, 75]
    assert parts[1][0] == "trajectory_0350" and parts[2][0] == "trajectory_0425"


def test_sim_label_rule():
    markers = np.array([[[0.0, 0.0], [0.0, 29.9], [0.0, 30.0]]])
    line = np.array([[[0.0, 0.0], [100.0, 0.0]]])
    assert sim_labels(markers, line, np.array([True])).tolist() == [[1, 1, 0]]
    assert sim_labels(markers, line, np.array([False])).tolist() == [[0, 0, 0]]


def test_sim_labels_bit_identical_to_the_summed_squares():
    """The fast distance (dx² + dy²) equals the original summed (..., 2) squares bit for bit, ties at the radius
    included, so training batches and every reference output are unchanged."""
    rng = np.random.default_rng(3)
    markers = rng.uniform(0, 2000, (4, 5, 127, 2)).astype(np.float32)
    line = (markers[:, :, :50] + rng.normal(0, 30, (4, 5, 50, 2))).astype(np.float32)
    line[0, 0, 0] = markers[0, 0, 7] + np.float32([30.0, 0.0])  # exactly on the radius: not positive
    contact = rng.random((4, 5)) < 0.8
    d2 = ((markers[..., :, None, :].astype(np.float64) - line[..., None, :, :]) ** 2).sum(-1)
    expected = ((d2.min(axis=-1) < 30.0 ** 2) & contact[..., None]).astype(np.int8)
    got = sim_labels(markers, line, contact)
    assert got.dtype == np.int8 and np.array_equal(got, expected)
    assert 0 < expected.mean() < 1


def test_rotation_permutation_is_consistent():
    rest = rest_layout("ideal")
    perms = rotation_permutations(rest)
    assert np.array_equal(perms[0], np.arange(127))
    for r in range(1, 6):
        moved = rotate_points(rest, 60 * r)[perms[r]]
        assert np.allclose(moved, rest, atol=1e-3)
    assert np.allclose(rotate_points(rest, 360), rest, atol=1e-3)


def _sim_seqs(rest, n_frames=48):
    rng = np.random.default_rng(0)
    markers = [(rest[None].repeat(n_frames, 0) + rng.normal(0, 1, (n_frames, 127, 2))).astype(np.float32)]
    line = np.stack([np.linspace(900, 1200, 50), np.full(50, 584.0)], 1)
    return Sequences("sim", ["t0"], markers, 24, centreline=[np.tile(line, (n_frames, 1, 1)).astype(np.float32)],
                     contact=[np.ones(n_frames, bool)])


@pytest.mark.parametrize("consistent", [False, True])
def test_gather_rotation_keeps_labels_with_markers(consistent):
    rest = rest_layout("ideal")
    clips = ClipSet(_sim_seqs(rest), 2, rest)
    assert len(clips) == 1
    m0, l0 = clips.gather([0])
    m1, l1 = clips.gather([0], rotations=[1], consistent=consistent)
    assert l0.sum() > 0 and l1.sum() == l0.sum()  # labels recomputed after rotating: same positives
    if consistent:  # nodes renumbered: each sits near its own rest site again
        assert np.abs(m1 - rest).max() < 10
    else:  # quirk 14: node i keeps its id while moving to another site
        assert np.abs(m1 - rest).max() > 50
        assert np.array_equal(l1, l0)


def test_lattice_rotation_moves_displacements_onto_the_sites():
    """`lattice`: every node sits at its own rest site plus a rotated displacement, labels carried with the marker.
    On the symmetric layout it is `consistent`; on the template the rest layout is not 6-fold symmetric about the
    rotation centre, so `consistent` adds a static offset that `lattice` does not."""
    ideal = rest_layout("ideal")
    clips = ClipSet(_sim_seqs(ideal), 2, ideal)
    m0, l0 = clips.gather([0], rotations=[0], lattice=True)
    assert np.array_equal(m0, clips.gather([0])[0]) and np.array_equal(l0, clips.gather([0])[1])
    mc, lc = clips.gather([0], rotations=[2], consistent=True)
    ml, ll = clips.gather([0], rotations=[2], lattice=True)
    assert np.allclose(ml, mc, atol=1e-3) and np.array_equal(ll, lc) and ll.sum() == l0.sum()

    template = rest_layout("template")
    clips = ClipSet(_sim_seqs(template), 2, template)
    perm = rotation_permutations(template)[1]
    m0, l0 = clips.gather([0])
    ml, ll = clips.gather([0], rotations=[1], lattice=True)
    mc, _ = clips.gather([0], rotations=[1], consistent=True)
    d0 = np.linalg.norm(m0 - template, axis=-1)[:, :, perm]  # displacement sizes, renumbered
    assert np.allclose(np.linalg.norm(ml - template, axis=-1), d0, atol=1e-3)  # only rotated: same sizes
    assert np.array_equal(ll, l0[:, :, perm])
    assert np.abs(np.linalg.norm(mc - template, axis=-1) - d0).max() > 5  # consistent: the layout's offset
