import numpy as np
import pytest

from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.features import clip_features, marker_feature_dim, static_marker_features
from palpation.graph.layout import rest_layout


@pytest.fixture(scope="module")
def rest():
    return rest_layout("ideal")


def test_feature_dims(rest):
    topo = clip_topology(spatial_edges(rest), 5)
    clips = np.random.default_rng(0).normal(rest, 2.0, (3, 5, 127, 2))
    f = clip_features(clips, rest, topo)
    assert marker_feature_dim(5) == 137
    assert f.x.shape == (3, 635, 137)
    assert f.spatial.shape == (3, 3420, 5) and f.temporal.shape == (3, 1016, 7)
    assert f.global_temporal.shape == (3, 8, 2)
    # one-hots: node t·127 + i has id i and time t
    assert np.array_equal(f.x[0, :, 5:132].argmax(1), np.tile(np.arange(127), 5))
    assert np.array_equal(f.x[0, :, 132:].argmax(1), np.repeat(np.arange(5), 127))
    assert np.allclose(f.x[..., :2], clips.reshape(3, 635, 2))


def test_edge_geometry_and_direction(rest):
    topo = clip_topology(spatial_edges(rest), 2)
    clips = np.random.default_rng(1).normal(rest, 2.0, (1, 2, 127, 2)).astype(np.float32)
    f = clip_features(clips, rest, topo)
    pos = clips.reshape(-1, 2)
    src, dst = topo.edge_index[:, topo.block("spatial")]
    vec = pos[dst] - pos[src]
    assert np.allclose(f.spatial[0, :, 1:3], vec, atol=1e-4)
    assert np.allclose(f.spatial[0, :, 0], np.linalg.norm(vec, axis=1), atol=1e-4)
    assert np.allclose(f.spatial[0, :, 3:5] * f.spatial[0, :, :1], vec, atol=1e-3)
    assert np.array_equal(f.temporal[0, :127, 5:], np.tile([0, 1], (127, 1)))  # forward
    assert np.array_equal(f.temporal[0, 127:, 5:], np.tile([1, 0], (127, 1)))  # backward
    assert np.array_equal(f.global_temporal[0], [[0, 1], [1, 0]])


def test_static_features_centre_is_zero(rest):
    s = static_marker_features(rest)
    assert np.array_equal(s[0], [0, 0, 0])
    assert np.allclose(np.linalg.norm(s[1:, 1:], axis=1), 1.0)


def test_rejects_nan(rest):
    topo = clip_topology(spatial_edges(rest), 1)
    clips = np.tile(rest, (1, 1, 1, 1))
    clips[0, 0, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        clip_features(clips, rest, topo)


def test_remove_common_motion_drops_the_field_translation_and_keeps_local_motion(rest):
    """The opt-in input transform (recipe field remove_common_motion): a per-frame translation of the whole field
    changes no feature, a single marker's motion relative to the others stays, `pos` stays raw; off, nothing moves."""
    topo = clip_topology(spatial_edges(rest), 5)
    clips = np.random.default_rng(2).normal(rest, 2.0, (2, 5, 127, 2)).astype(np.float32)
    drift = np.random.default_rng(3).normal(0, 4.0, (2, 5, 1, 2)).astype(np.float32)  # per clip and frame
    a = clip_features(clips, rest, topo, remove_common_motion=True)
    b = clip_features(clips + drift, rest, topo, remove_common_motion=True)
    for field in ("x", "spatial", "temporal"):
        assert np.allclose(getattr(a, field), getattr(b, field), atol=1e-3)
    assert np.allclose(b.pos, (clips + drift).reshape(2, 635, 2))  # the vessel map's positions: raw
    plain = clip_features(clips + drift, rest, topo)
    assert not np.allclose(plain.x[..., :2], a.x[..., :2], atol=1e-2)  # off: the drift is in the features
    assert np.array_equal(plain.x, clip_features(clips + drift, rest, topo, remove_common_motion=False).x)
    # one marker pushed 5 px: its position relative to a neighbour still moves by the full 5 px
    pushed = clips.copy()
    pushed[:, :, 40] += (5.0, 0.0)
    c = clip_features(pushed, rest, topo, remove_common_motion=True)
    rel = lambda f: f.x[0, 40, :2] - f.x[0, 41, :2]
    assert np.allclose(rel(c) - rel(a), (5.0, 0.0), atol=1e-3)
