"""Optuna search of the twin parameters against the measured flat-tip photos (docs/calibration.md)."""
