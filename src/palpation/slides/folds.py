"""Split measured slides by trial for the slide loop (issue 12): a twin is fitted on one fold's trials and
scored on the other's, so every held-out number comes from trials its twin never saw."""

from __future__ import annotations

FOLDS = ("odd", "even")


def trial_folds(trial_numbers: list[int]) -> dict[str, list[int]]:
    """{"odd": indices of trials with an odd 1-based number, "even": the rest}; both non-empty."""
    numbers = [int(t) for t in trial_numbers]
    if len(set(numbers)) != len(numbers):
        raise ValueError(f"trial numbers must be unique to split by trial, got {numbers}")
    folds = {"odd": [i for i, t in enumerate(numbers) if t % 2 == 1],
             "even": [i for i, t in enumerate(numbers) if t % 2 == 0]}
    empty = [k for k, v in folds.items() if not v]
    if empty:
        raise ValueError(f"trials {numbers} leave fold(s) {empty} empty; the slide loop needs odd and even trials")
    return folds


def other(fold: str) -> str:
    if fold not in FOLDS:
        raise ValueError(f"unknown fold '{fold}'; use one of {FOLDS}")
    return FOLDS[1 - FOLDS.index(fold)]
