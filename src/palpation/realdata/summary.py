"""One table for every real set: trials, frames, markers per frame and positive rate vs the reference.

Sets come in two layouts: a dense (trials, T, 127, 2) `markers` array (Silicone), or flat
(frames, 127, 2) arrays cut into trials by `trial_offsets` (Meat, whose trials differ in length).
The positive rate is taken on the frames that are clip centres at L = 5, as the reference counts
it: `central_trim` frames are dropped at both ends of each sequence (2 for Silicone's 16-frame
videos, 0 for Meat, whose panel only ever showed clip centres). Labels < 0 (unknown) are skipped.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from palpation.readers import read_npz

COLUMNS = ("dataset", "trials", "frames", "markers_per_frame", "positive_rate", "reference_positive_rate")
# SPEC §13.4-13.5 and §7: central-frame positive rates of the reference's sets.
REFERENCE_POSITIVE_RATE = {"silicone": 0.1133, "meat": 0.0651, "sim": 0.042}


@dataclass(frozen=True)
class DatasetSpec:
    name: str
    path: str
    central_trim: int = 0
    reference_positive_rate: float | None = None


def load_sequences(path: str | os.PathLike, name: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(markers (T, M, 2), labels (T, M)) per trial] from a set's npz, whichever layout it uses."""
    path = Path(path)
    fix = f"build it again (snakemake --cores 2 {path})"
    npz = read_npz(path, ("markers", "labels"), fix, f"{name} set", finite=("markers",))
    markers, labels = npz["markers"], npz["labels"]
    offsets = npz.get("trial_offsets")
    if markers.shape[:-1] != labels.shape or markers.shape[-1] != 2:
        raise ValueError(f"{path}: markers {markers.shape} and labels {labels.shape} do not pair up "
                         f"as (..., M, 2) and (..., M); {fix}")
    if offsets is not None and markers.ndim == 3:
        if offsets.ndim != 1 or offsets[0] != 0 or offsets[-1] != len(markers) or np.any(np.diff(offsets) <= 0):
            raise ValueError(f"{path}: trial_offsets {offsets.tolist()[:12]} do not cut {len(markers)} frames; {fix}")
        return [(markers[a:b], labels[a:b]) for a, b in zip(offsets[:-1], offsets[1:])]
    if markers.ndim == 4:
        return list(zip(markers, labels))
    raise ValueError(f"{path}: markers {markers.shape} is neither (trials, T, M, 2) nor (frames, M, 2) "
                     f"with 'trial_offsets'")


def summarise(spec: DatasetSpec, sequences: list[tuple[np.ndarray, np.ndarray]]) -> dict:
    """One table row for a set."""
    k = spec.central_trim
    short = [len(lab) for _, lab in sequences if len(lab) <= 2 * k]
    if short:
        raise ValueError(f"{spec.path}: a sequence of {short[0]} frames has no central frame after "
                         f"trimming {k} at each end (central_trim={k})")
    central = np.concatenate([lab[k:len(lab) - k].ravel() for _, lab in sequences])
    known = central[central >= 0]
    return {
        "dataset": spec.name,
        "trials": len(sequences),
        "frames": int(sum(len(lab) for _, lab in sequences)),
        "markers_per_frame": int(sequences[0][1].shape[1]),
        "positive_rate": float((known == 1).mean()) if known.size else float("nan"),
        "reference_positive_rate": spec.reference_positive_rate,
    }


def summary_table(specs: list[DatasetSpec]) -> pd.DataFrame:
    """Rows in the order given; every input must exist (a missing one raises, naming the file)."""
    return pd.DataFrame([summarise(s, load_sequences(s.path, s.name)) for s in specs], columns=COLUMNS)


def specs_from_mapping(datasets: Mapping[str, Mapping]) -> list[DatasetSpec]:
    """{name: {path, central_trim, reference_positive_rate}} -> specs (reference defaults per name)."""
    return [DatasetSpec(name=name, path=str(d["path"]), central_trim=int(d.get("central_trim", 0)),
                        reference_positive_rate=d.get("reference_positive_rate",
                                                      REFERENCE_POSITIVE_RATE.get(name)))
            for name, d in datasets.items()]


def to_markdown(table: pd.DataFrame) -> str:
    """A GitHub table plus a note on how the rates were counted."""
    def cell(v):
        if isinstance(v, float):
            return "" if np.isnan(v) else f"{v:.4f}"
        return "" if v is None else str(v)

    lines = ["| " + " | ".join(table.columns) + " |", "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in table.itertuples(index=False)]
    lines += ["", "positive_rate: label-1 share of the markers on clip-centre frames (L = 5), as the "
              "reference counts it; frames: all frames of the set."]
    return "\n".join(lines) + "\n"
