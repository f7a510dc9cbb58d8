"""Sim-to-real transfer beyond the paper (docs/transfer.md): the selection rules and the transfer table, the
seed-ensemble pseudo-label filter, and the latent press depth of real slides from a twin-made lookup."""
