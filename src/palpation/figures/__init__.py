"""Figures: one module per figure; drawing functions take `ax` first."""
