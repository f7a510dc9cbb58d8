"""The spatio-temporal GINE model (SPEC §9), its training loop (§10) and checkpoints."""

from palpation.model.config import ModelConfig, TrainConfig
from palpation.model.stgnn import STGNN, count_parameters

__all__ = ["ModelConfig", "TrainConfig", "STGNN", "count_parameters"]
