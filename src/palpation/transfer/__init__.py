"""Sim-to-real transfer beyond the paper (docs/transfer.md): the selection rules and the transfer table, and the
latent press depth of real slides from a twin-made lookup. The pseudo-label filter and the self-training set are a
job's training data: palpation.model.pseudo_labels and palpation.model.self_training."""
