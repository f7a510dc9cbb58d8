import numpy as np
import pytest

from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.features import clip_features
from palpation.graph.layout import rest_layout
from palpation.graph.normalise import NormStats


def _feats(n=4, seed=0):
    rest = rest_layout("ideal")
    topo = clip_topology(spatial_edges(rest), 3)
    clips = np.random.default_rng(seed).normal(rest, 5.0, (n, 3, 127, 2))
    labels = np.zeros((n, 3, 127), np.int8)
    labels[:, :, :10] = 1
    return clip_features(clips, rest, topo), labels


def test_round_trip_and_unit_scale():
    feats, labels = _feats()
    stats = NormStats.from_chunks([(feats, labels)], "sample")
    norm = stats.apply(feats)
    back = stats.invert(norm)
    for a, b in ((feats.x, back.x), (feats.spatial, back.spatial), (feats.temporal, back.temporal)):
        assert np.allclose(a, b, atol=1e-3)
    cols = norm.x[..., :3].reshape(-1, 3)
    assert np.allclose(cols.mean(0), 0, atol=1e-4) and np.allclose(cols.std(0, ddof=1), 1, atol=1e-4)
    assert np.array_equal(norm.x[..., 3:], feats.x[..., 3:])  # only columns 0-2 are scaled
    assert np.array_equal(norm.spatial[..., 3:], feats.spatial[..., 3:])
    assert np.array_equal(norm.pos, feats.pos)
    assert stats.alpha == 1 - 10 / 127


def test_chunks_equal_one_pass_and_dict_round_trip():
    feats, labels = _feats(6)
    whole = NormStats.from_chunks([(feats, labels)], "full")
    halves = [(type(feats)(feats.x[s], feats.spatial[s], feats.temporal[s], feats.global_temporal[s],
                           feats.pos[s]), labels[s]) for s in (slice(0, 3), slice(3, 6))]
    parts = NormStats.from_chunks(halves, "full")
    assert np.allclose(whole.node_std, parts.node_std) and whole.alpha == parts.alpha
    assert NormStats.from_dict(whole.to_dict()) == whole


def test_statistics_of_older_checkpoints_load_without_the_input_transform():
    """remove_common_motion joined NormStats later: a checkpoint's dict without it loads as off; a dict missing a
    field without a default is still refused."""
    from palpation.graph.normalise import NormStats

    d = {"node_mean": (0, 0, 0), "node_std": (1, 1, 1), "spatial_mean": (0, 0, 0), "spatial_std": (1, 1, 1),
         "temporal_mean": (0, 0, 0), "temporal_std": (1, 1, 1), "alpha": 0.9, "n_clips": 4, "mode": "sample"}
    assert NormStats.from_dict(d).remove_common_motion is False
    assert NormStats.from_dict({**d, "remove_common_motion": True}).remove_common_motion is True
    with pytest.raises(ValueError, match="alpha"):
        NormStats.from_dict({k: v for k, v in d.items() if k != "alpha"})
