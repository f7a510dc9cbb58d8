"""Clip graphs of marker sequences (SPEC §8): topology, features, normalisation, augmentation, clips."""

from palpation.graph.edges import ClipTopology, clip_topology, spatial_edges
from palpation.graph.features import ClipFeatures, clip_features, static_marker_features
from palpation.graph.normalise import NormStats

__all__ = ["ClipTopology", "clip_topology", "spatial_edges", "ClipFeatures", "clip_features",
           "static_marker_features", "NormStats"]
