"""Spatio-temporal GINE network (SPEC §9): one logit per marker node of a clip graph.

Per-type encoders (Linear-ReLU-Linear) embed marker nodes and spatial / temporal / global-temporal
edges; global nodes and global-spatial edges are learned vectors. Each embedding gets an 8-d type tag
(Embedding(6, 8)). Three residual GINE blocks (L_d -> L_d -> L_d -> 1), then a late-fusion head over
the input embedding and all block outputs. Global-node outputs are dropped.
"""

from __future__ import annotations

import torch
from torch import nn
from torch_geometric.data import Data
from torch_geometric.nn import GINEConv

from palpation.graph.features import marker_feature_dim
from palpation.model.config import ModelConfig

MARKER, GLOBAL, SPATIAL, TEMPORAL, GLOBAL_SPATIAL, GLOBAL_TEMPORAL = range(6)


def encoder(in_dim: int, width: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(in_dim, width), nn.ReLU(), nn.Linear(width, width))


class Block(nn.Module):
    """out = Drop(ReLU(BN(GINEConv(x)))) + residual(x); eps = 0, not trained, no edge_dim."""

    def __init__(self, in_dim: int, latent: int, out_dim: int, dropout: float):
        super().__init__()
        mlp = nn.Sequential(nn.Linear(in_dim, latent), nn.ReLU(), nn.Dropout(dropout),
                            nn.Linear(latent, latent), nn.ReLU(), nn.Dropout(dropout),
                            nn.Linear(latent, out_dim))
        self.conv = GINEConv(mlp)
        self.bn = nn.BatchNorm1d(out_dim)
        self.drop = nn.Dropout(dropout)
        self.residual = nn.Identity() if in_dim == out_dim else nn.Linear(in_dim, out_dim)

    def forward(self, x, edge_index, edge_attr):
        return self.drop(torch.relu(self.bn(self.conv(x, edge_index, edge_attr)))) + self.residual(x)


class STGNN(nn.Module):
    def __init__(self, clip_len: int, cfg: ModelConfig = ModelConfig()):
        super().__init__()
        s, ld, k = cfg.encoder_width, cfg.latent_width, cfg.skip_width
        self.clip_len = clip_len
        self.enc_marker = encoder(marker_feature_dim(clip_len), s)
        self.enc_spatial = encoder(5, s)
        self.enc_temporal = encoder(7, s)
        self.enc_global_temporal = encoder(2, s)
        self.global_node = nn.Parameter(torch.randn(1, s))
        self.global_spatial_edge = nn.Parameter(torch.randn(1, s))
        self.type_tag = nn.Embedding(6, cfg.type_dim)
        self.input_drop = nn.Dropout(cfg.input_dropout)
        self.blocks = nn.ModuleList([Block(ld, ld, ld, cfg.dropout), Block(ld, ld, ld, cfg.dropout),
                                     Block(ld, ld, 1, cfg.dropout)])
        self.skips = nn.ModuleList([nn.Linear(ld, k), nn.Linear(ld, k), nn.Linear(ld, k), nn.Linear(1, k)])
        self.head = nn.Sequential(nn.Linear(4 * k, 2 * k), nn.ReLU(), nn.Dropout(cfg.dropout),
                                  nn.Linear(2 * k, 1))

    def _tag(self, h: torch.Tensor, kind: int) -> torch.Tensor:
        tag = self.type_tag.weight[kind].expand(h.shape[0], -1)
        return torch.cat([h, tag], dim=1)

    def forward(self, data: Data) -> torch.Tensor:
        """Logits (n_marker_nodes,) in the batch's marker-node order."""
        n_marker = data.x.shape[0]
        nodes = torch.cat([self._tag(self.enc_marker(data.x), MARKER),
                           self._tag(self.global_node.expand(data.num_global, -1), GLOBAL)])
        edges = torch.cat([
            self._tag(self.enc_spatial(data.edge_attr_spatial), SPATIAL),
            self._tag(self.enc_temporal(data.edge_attr_temporal), TEMPORAL),
            self._tag(self.global_spatial_edge.expand(data.num_global_spatial, -1), GLOBAL_SPATIAL),
            self._tag(self.enc_global_temporal(data.edge_attr_global_temporal), GLOBAL_TEMPORAL),
        ])
        h = self.input_drop(nodes)
        edges = self.input_drop(edges)
        hs = [h]
        for block in self.blocks:
            h = block(h, data.edge_index, edges)
            hs.append(h)
        # global outputs are dropped before the head (it has no BN, so slicing first is equivalent)
        fused = torch.cat([skip(x[:n_marker]) for skip, x in zip(self.skips, hs)], dim=1)
        return self.head(fused).squeeze(-1)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
