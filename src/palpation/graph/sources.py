"""Marker sequences from the three datasets (SPEC §1.1, §7, §10), as plain numpy lists.

* Sim: a folder of `trajectory_*.npz` (markers (F,127,2), centreline_px (F,P,2), contact (F,)) with a
  `manifest.json`; split 70/15/15 by sorted trajectory id. Labels are recomputed per clip after
  augmentation (30 px rule), so the files' own `labels` are not read.
* Silicone: one npz, `markers` (N,T,127,2) and `labels` (N,T,127); always used whole.
* Meat: flat per-state arrays cut into trials by `trial_offsets`, splits in the JSON beside it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from palpation.readers import read_json, read_npz
from palpation.twin.output import SIM_FIX, read_sim_manifest
from palpation.markers.lattice import N_MARKERS

SPLITS = ("train", "val", "test", "all")
SIM_STRIDE = 24  # frames between clip frames in Sim (SPEC §8.3)


@dataclass
class Sequences:
    """Marker sequences of one dataset split. Sim carries centreline+contact instead of labels."""

    name: str
    ids: list
    markers: list  # (T, 127, 2) float32 px
    stride: int
    labels: list | None = None  # (T, 127) int8 (real data)
    centreline: list | None = None  # (T, P, 2) float32 px (Sim)
    contact: list | None = None  # (T,) bool (Sim)
    window: str = "full"  # full: windows inside the sequence | centred: one per frame, edges replicated

    def __post_init__(self):
        for sid, m in zip(self.ids, self.markers):
            if m.ndim != 3 or m.shape[1:] != (N_MARKERS, 2):
                raise ValueError(f"{self.name} sequence {sid}: markers must be (T, {N_MARKERS}, 2), got {m.shape}")
        if (self.labels is None) == (self.centreline is None):
            raise ValueError(f"{self.name}: give either labels (real data) or centreline+contact (Sim)")


def split_sorted(ids: list, split: str, fractions=(0.7, 0.85)) -> list:
    """SPEC §7: sort, cut at int(0.7 n) and int(0.85 n)."""
    if split not in SPLITS:
        raise ValueError(f"unknown split '{split}': use one of {SPLITS}")
    ids = sorted(ids)
    a, b = int(fractions[0] * len(ids)), int(fractions[1] * len(ids))
    return {"train": ids[:a], "val": ids[a:b], "test": ids[b:], "all": ids}[split]


def sim_trajectory_files(manifest: str | Path) -> list[Path]:
    """The trajectory files the manifest names, and only those: other npz files in the folder (a previous
    run's) are never read. An empty list (every trajectory of the run diverged) is refused
    (twin.output.read_sim_manifest, the reader of the format)."""
    return read_sim_manifest(manifest)[1]


def load_sim(manifest: str | Path, split: str, stride: int = SIM_STRIDE) -> Sequences:
    files = {f.stem: f for f in sim_trajectory_files(manifest)}
    ids = split_sorted(list(files), split)
    markers, centreline, contact = [], [], []
    for sid in ids:
        z = read_npz(files[sid], ("markers", "centreline_px", "contact"), SIM_FIX, finite=("markers", "centreline_px"),
                     shapes={"markers": (None, N_MARKERS, 2), "centreline_px": (None, None, 2), "contact": (None,)})
        markers.append(z["markers"].astype(np.float32))
        centreline.append(z["centreline_px"].astype(np.float32))
        contact.append(z["contact"].astype(bool))
    return Sequences(f"sim/{split}", ids, markers, stride, centreline=centreline, contact=contact)


def load_silicone(path: str | Path) -> Sequences:
    z = read_npz(path, ("markers", "labels"), "rerun the silicone_set rule", "Silicone set", finite=("markers",),
                 shapes={"markers": (None, None, N_MARKERS, 2)})
    markers, labels = z["markers"].astype(np.float32), z["labels"].astype(np.int8)
    if labels.shape != markers.shape[:3]:
        raise ValueError(f"Silicone set {path}: labels {labels.shape} do not match markers {markers.shape}; rerun "
                         "the silicone_set rule")
    ids = [f"silicone_{i:02d}" for i in range(len(markers))]
    return Sequences("silicone", ids, list(markers), 1, labels=list(labels))


def load_meat(path: str | Path, split: str) -> Sequences:
    """Meat trials of `split` (train / val per SPEC §10, or all).

    Layout (palpation.realdata.meat): flat `markers` (219,127,2) / `labels` (219,127) over the viewer
    states, cut into trials by `trial_offsets`; the JSON beside it lists the trials with their split.
    The states are the central frames 2..T-3 of each trial, so windows are centred on every state and
    the two missing frames at each end are replaced by the nearest available one (`window="centred"`);
    this scores exactly the paper's 219 central frames (27,813 nodes).
    """
    path = Path(path)
    layout = path.with_suffix(".json")
    if split not in ("train", "val", "all"):
        raise ValueError(f"Meat split must be train, val or all, got '{split}'")
    fix = "rerun the meat_set rule"
    trials = read_json(layout, fix, "Meat layout", keys=("trials",))["trials"]
    if not isinstance(trials, list) or not all(isinstance(r, dict) and {"split", "trial_id"} <= r.keys()
                                               for r in trials):
        raise ValueError(f"Meat layout {layout}: `trials` must be a list of rows with `trial_id` and `split`; {fix}")
    z = read_npz(path, ("markers", "labels", "trial_offsets"), fix, "Meat set", finite=("markers",),
                 shapes={"markers": (None, N_MARKERS, 2), "labels": (None, N_MARKERS), "trial_offsets": (None,)},
                 dtypes={"trial_offsets": "iu"})
    markers, labels, offsets = z["markers"].astype(np.float32), z["labels"].astype(np.int8), z["trial_offsets"]
    if (len(offsets) != len(trials) + 1 or offsets[0] != 0 or offsets[-1] != len(markers)
            or np.any(np.diff(offsets) < 0)):
        raise ValueError(f"Meat set {path}: trial_offsets {offsets.tolist()[:12]} do not cut {len(markers)} states "
                         f"into the {len(trials)} trials of {layout}; {fix}")
    keep = [(t, a, b) for t, a, b in zip(trials, offsets[:-1], offsets[1:]) if split in ("all", t["split"])]
    if not keep:
        raise ValueError(f"{path}: no Meat trials in split '{split}'")
    return Sequences(f"meat/{split}", [f"trial{t['trial_id']:02d}" for t, _, _ in keep],
                     [markers[a:b] for _, a, b in keep], 1, labels=[labels[a:b] for _, a, b in keep],
                     window="centred")


def load_dataset(name: str, path: str | Path, split: str) -> Sequences:
    """`sim` / `silicone` / `meat`; Silicone ignores `split` (always whole), Meat maps test -> all."""
    if name == "sim":
        return load_sim(path, split)
    if name == "silicone":
        return load_silicone(path)
    if name == "meat":
        return load_meat(path, "all" if split == "test" else split)
    raise ValueError(f"unknown dataset '{name}': use sim, silicone or meat")
