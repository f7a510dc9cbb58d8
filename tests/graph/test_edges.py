import numpy as np
import pytest

from palpation.graph.edges import clip_topology, keep_counts, spatial_edges
from palpation.graph.layout import rest_layout
from palpation.markers.lattice import neighbours


@pytest.fixture(scope="module")
def rest():
    return rest_layout("ideal")


def test_spatial_edges_684_with_6_4_3_neighbours(rest):
    adj = spatial_edges(rest)
    assert adj.shape == (684, 2)
    in_degree = np.bincount(adj[:, 1], minlength=127)
    assert np.array_equal(in_degree, keep_counts(rest))
    assert np.all(in_degree[:91] == 6) and sorted(np.bincount(in_degree[91:])[3:5]) == [6, 30]
    assert not np.any(adj[:, 0] == adj[:, 1])  # self dropped
    nb = neighbours(rest)
    assert all(s in nb[d] for s, d in adj)  # only lattice neighbours on a regular hexagon


def test_spatial_edges_on_rest_template():
    template = rest_layout("template")
    assert spatial_edges(template).shape == (684, 2)
    assert np.array_equal(np.bincount(keep_counts(template)), [0, 0, 0, 6, 30, 0, 91])


@pytest.mark.parametrize("clip_len", [1, 3, 5, 7])
def test_clip_edge_counts(rest, clip_len):
    topo = clip_topology(spatial_edges(rest), clip_len)
    big_l = clip_len
    assert topo.counts == {"spatial": 684 * big_l, "temporal": 2 * (big_l - 1) * 127,
                           "global_spatial": 2 * 127 * big_l, "global_temporal": 2 * (big_l - 1)}
    assert topo.edge_index.shape[1] == sum(topo.counts.values())
    assert topo.edge_index.max() == topo.n_nodes - 1
    if clip_len == 5:
        assert topo.edge_index.shape == (2, 5714) and topo.n_nodes == 640


def test_clip_edge_blocks(rest):
    topo = clip_topology(spatial_edges(rest), 5)
    ei = topo.edge_index
    sp, tp = ei[:, topo.block("spatial")], ei[:, topo.block("temporal")]
    assert np.all(sp // 127 == sp[0] // 127)  # spatial edges stay in one frame
    assert np.all(np.abs(tp[1] - tp[0]) == 127)  # temporal: same marker, adjacent frame
    gs = ei[:, topo.block("global_spatial")]
    assert np.all((gs[0] >= 635) ^ (gs[1] >= 635))  # exactly one end is a global node
    gt = ei[:, topo.block("global_temporal")]
    assert np.all(gt >= 635) and np.all(np.abs(gt[1] - gt[0]) == 1)


def test_batched_edge_index(rest):
    topo = clip_topology(spatial_edges(rest), 3)
    assert np.array_equal(topo.batched_edge_index(1), topo.edge_index)
    ei = topo.batched_edge_index(2)
    m = topo.n_markers
    graph = np.where(ei < 2 * m, ei // m, (ei - 2 * m) // 3)  # which clip each endpoint belongs to
    assert ei.shape[1] == 2 * topo.edge_index.shape[1]
    assert np.array_equal(graph[0], graph[1])  # no edge crosses clips
