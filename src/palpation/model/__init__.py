"""The spatio-temporal GINE model (SPEC §9), its training loop (§10) and checkpoints."""

from palpation.model.config import ModelConfig, TrainConfig

__all__ = ["ModelConfig", "TrainConfig", "STGNN", "count_parameters"]


def __getattr__(name):
    # torch and torch_geometric load only when the model is used: the Snakefile imports palpation.model.config
    # (the train schema) and recipe switches on every parse, where they would add seconds to each snakemake call
    if name in ("STGNN", "count_parameters"):
        from palpation.model import stgnn

        return getattr(stgnn, name)
    raise AttributeError(f"module 'palpation.model' has no attribute {name!r}")
