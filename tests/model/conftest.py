"""Fixtures shared by the model tests."""

import pytest

from palpation.graph.clips import ClipSet
from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.layout import rest_layout
from palpation.graph.sources import load_dataset
from palpation.graph.synthetic import write_meat


@pytest.fixture(scope="module")
def meat_l2(tmp_path_factory):
    """(rest, topology, {train, val} clip sets) of a tiny synthetic Meat set in 2-frame clips: temporal edges, half
    the nodes of 3 frames, for trainings of a few seconds."""
    rest = rest_layout("ideal")
    path = write_meat(tmp_path_factory.mktemp("meat") / "meat.npz", rest, n_frames=(8,) * 5, n_val=2)
    topo = clip_topology(spatial_edges(rest), 2)
    return rest, topo, {s: ClipSet(load_dataset("meat", path, s), 2, rest) for s in ("train", "val")}
