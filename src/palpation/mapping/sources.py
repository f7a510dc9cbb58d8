"""Test sequences with a pose per frame, in the order the evaluation pooled them (SPEC §8.3, §12).

Markers, labels, stride and window mode come from the training stage's own loaders
(`palpation.graph.sources.load_dataset`), so the sequences are the ones the scores were pooled over:
Silicone videos 1-10; Meat trials 1-10; Sim trajectories of the split, sorted by name (SPEC §7).
We add a pose per frame and say which map each sequence draws into: Silicone one map for all sweeps,
Meat one per trial, Sim one per slide.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from palpation.graph.sources import SIM_STRIDE, load_dataset, load_sim, sim_trajectory_files
from palpation.mapping.meat_poses import MeatPoseFit, check_meat_poses, fit_meat_poses
from palpation.mapping.silicone_poses import SweepLayout, silicone_poses
from palpation.readers import read_npz
from palpation.realdata.meat import TRIALS


@dataclass
class MapSource:
    dataset: str  # sim | silicone | meat
    ids: list
    markers: list  # (T, 127, 2) sensor px per sequence
    labels: list | None  # (T, 127) per sequence, to check the scores' alignment
    poses: list  # (T, 2) robot/pose xy mm, or (T, 4, 4) T_BA in metres (Sim)
    stride: int
    map_of_seq: np.ndarray  # (n_seq,) map index of each sequence
    map_names: list
    meta: dict
    window: str = "full"  # the Sequences' window mode (palpation.graph.clips.ClipSet)

    def __post_init__(self):
        for sid, m, p in zip(self.ids, self.markers, self.poses):
            if len(m) != len(p):
                raise ValueError(f"{self.dataset} sequence {sid}: {len(m)} frames of markers but {len(p)} poses; "
                                 f"the pose source must give one pose per recorded frame")


def silicone_source(path: str | Path, layout: SweepLayout = SweepLayout()) -> MapSource:
    """The 10 Silicone videos with reconstructed robot poses, all drawn into one map."""
    seqs = load_dataset("silicone", path, "test")
    poses = silicone_poses(layout)  # (10 videos, 16 frames, 2)
    n_frames = sorted({len(m) for m in seqs.markers})
    if len(seqs.markers) != len(poses) or n_frames != [poses.shape[1]]:
        raise ValueError(f"{path}: {len(seqs.markers)} videos of {n_frames} frames; the sweep layout knows "
                         f"{poses.shape[0]} x {poses.shape[1]} (SPEC §13.4)")
    return MapSource("silicone", list(seqs.ids), [m.astype(np.float64) for m in seqs.markers], list(seqs.labels),
                     list(poses), seqs.stride, np.zeros(len(seqs.ids), np.int64), ["silicone"],
                     {"layout": layout.__dict__}, seqs.window)


def meat_trials(path: str | Path) -> list[dict]:
    """Per-trial arrays of the flat Meat set (palpation.realdata.meat.build_meat), with trial frames."""
    data = read_npz(path, ("markers", "labels", "frame", "trial_offsets"), "run the meat_set rule first",
                    "Meat set", finite=("markers",), dtypes={"trial_offsets": "iu", "frame": "iu"})
    off = data["trial_offsets"]
    if len(off) - 1 != len(TRIALS):
        raise ValueError(f"{path}: {len(off) - 1} trials in trial_offsets, expected {len(TRIALS)}")
    return [{"markers": data["markers"][a:b].astype(np.float64), "labels": data["labels"][a:b].astype(np.int8),
             "frame": data["frame"][a:b], "description": t.description, "name": f"trial_{t.trial_id:02d}"}
            for t, a, b in zip(TRIALS, off[:-1], off[1:])]


def meat_source(path: str | Path, fit: MeatPoseFit | None = None) -> MapSource:
    """The 10 Meat trials, one map each, poses from the straight-slide fit (meat_poses)."""
    trials = meat_trials(path)
    seqs = load_dataset("meat", path, "test")
    if [len(m) for m in seqs.markers] != [len(t["frame"]) for t in trials]:
        raise ValueError(f"{path}: the training loader cuts the trials into {[len(m) for m in seqs.markers]} "
                         f"frames, the set's trial_offsets into {[len(t['frame']) for t in trials]}")
    fit = fit or fit_meat_poses(trials)
    poses = [fit.pose_xy(i, t["frame"]) for i, t in enumerate(trials)]
    names = [t["name"] for t in trials]
    return MapSource("meat", names, [m.astype(np.float64) for m in seqs.markers], list(seqs.labels), poses,
                     seqs.stride, np.arange(len(trials)), names,
                     {"poses": fit.to_dict(), "pose_check": check_meat_poses(trials, fit)}, seqs.window)


def sim_source(manifest: str | Path, split: str = "test", stride: int = SIM_STRIDE) -> MapSource:
    """Sim trajectories of `split` with their recorded T_BA (metres), one map per slide."""
    seqs = load_sim(manifest, split, stride)
    files = {f.stem: f for f in sim_trajectory_files(manifest)}
    labels, poses = [], []
    for sid in seqs.ids:
        z = read_npz(files[sid], ("T_BA",), "the Sim map needs recorded poses (SPEC quirk 17): re-simulate with the "
                     "twin runner of docs/sim_format.md", finite=("T_BA",), shapes={"T_BA": (None, 4, 4)})
        labels.append(z["labels"].astype(np.int8) if "labels" in z else None)
        poses.append(z["T_BA"].astype(np.float64))
    if not seqs.ids:
        raise ValueError(f"{manifest}: no trajectories in split '{split}'")
    labels = None if any(lab is None for lab in labels) else labels
    return MapSource("sim", list(seqs.ids), [m.astype(np.float64) for m in seqs.markers], labels, poses,
                     seqs.stride, np.arange(len(seqs.ids)), list(seqs.ids), {"split": split}, seqs.window)
