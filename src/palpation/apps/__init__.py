"""Hydra entry points, one per pipeline stage."""
