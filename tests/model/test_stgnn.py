import numpy as np
import pytest
import torch

from palpation.graph.batch import make_batch
from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.features import clip_features
from palpation.graph.layout import rest_layout
from palpation.graph.normalise import NormStats
from palpation.model import STGNN, ModelConfig, count_parameters

LARGE = ModelConfig()
COMPACT = ModelConfig("compact", 56, 64, 32)


@pytest.mark.parametrize("clip_len, large, compact", [(1, 1_043_405, 69_677), (3, 1_043_901, 69_789),
                                                      (5, 1_044_397, 69_901), (7, 1_044_893, 70_013)])
def test_parameter_counts_match_spec(clip_len, large, compact):
    assert count_parameters(STGNN(clip_len, LARGE)) == large
    assert count_parameters(STGNN(clip_len, COMPACT)) == compact


def test_widths_must_add_up():
    with pytest.raises(ValueError, match="latent_width"):
        ModelConfig("bad", 56, 60, 32)


def test_one_logit_per_marker_node():
    rest = rest_layout("ideal")
    topo = clip_topology(spatial_edges(rest), 3)
    clips = np.random.default_rng(0).normal(rest, 2.0, (2, 3, 127, 2))
    labels = np.zeros((2, 3, 127), np.int8)
    stats = NormStats.from_chunks([(clip_features(clips, rest, topo), labels + 1)], "sample")
    torch.manual_seed(0)
    model = STGNN(3, COMPACT).eval()
    batch = make_batch(clips, labels, rest, topo, stats)
    out = model(batch)
    assert out.shape == (2 * 3 * 127,)
    # clips in a batch do not talk to each other: scoring one alone gives the same logits
    alone = model(make_batch(clips[1:], labels[1:], rest, topo, stats))
    assert torch.allclose(out[3 * 127:], alone, atol=1e-5)
