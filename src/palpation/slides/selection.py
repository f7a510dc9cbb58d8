"""The part of a sequence set the slide loop works on: the chosen trials and frames (conf/slide_loop.yaml
`trials`, `frames`), for the slide loop's app and the judge's budget alike."""

from __future__ import annotations

import dataclasses

from palpation.measured_sequences import SequenceSet


def select(sset: SequenceSet, trials, frames) -> tuple[SequenceSet, list[int]]:
    """The chosen 1-based trials and [first, end) frames of a set, and the trials' numbers."""
    numbers = list(range(1, sset.n_trials + 1)) if trials is None else [int(t) for t in trials]
    bad = [t for t in numbers if not 1 <= t <= sset.n_trials]
    if bad:
        raise ValueError(f"conf/slide_loop.yaml: trials {bad} outside 1..{sset.n_trials} of the sequence set")
    sub = sset.subset([t - 1 for t in numbers])
    if frames is not None:
        first, end = (int(f) for f in frames)
        if not 0 <= first < end <= sset.n_frames or end - first < 2:
            raise ValueError(f"conf/slide_loop.yaml: frames [{first}, {end}) must hold >= 2 of 0..{sset.n_frames}")
        cut = slice(first, end)
        sub = dataclasses.replace(sub, markers=sub.markers[:, cut], displacement=sub.displacement[:, cut],
                                  found=sub.found[:, cut], pose_mm=sub.pose_mm[:, cut],
                                  labels=None if sub.labels is None else sub.labels[:, cut])
    return sub, numbers
