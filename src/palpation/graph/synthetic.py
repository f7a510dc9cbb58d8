"""Small synthetic datasets in the on-disk formats of Sim, Silicone and Meat, for tests and smoke runs.

A straight vessel sweeps across the image; while in contact, markers near it are pushed away from it
by a few pixels, so a model has something to learn. Labels follow the Sim rule (< 30 px and contact).
Nothing here resembles the real sensor beyond the file formats.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from palpation.graph.augment import sim_labels
from palpation.io import save_json, save_npz

N_LINE = 50


def sequence(rest: np.ndarray, n_frames: int, rng: np.random.Generator, vessel: bool = True):
    """-> markers (T,127,2) float32, centreline (T,50,2) float32, contact (T,) bool, labels (T,127) int8."""
    t = np.linspace(0.0, 1.0, n_frames)
    angle = rng.uniform(-0.3, 0.3)
    y0 = rest[:, 1].min() - 60 + (np.ptp(rest[:, 1]) + 120) * t  # the vessel crosses the whole dome
    xs = np.linspace(rest[:, 0].min() - 100, rest[:, 0].max() + 100, N_LINE)
    cx = xs.mean()
    line = np.stack([np.broadcast_to(xs, (n_frames, N_LINE)),
                     y0[:, None] + np.tan(angle) * (xs - cx)], axis=-1)
    if not vessel:
        line = line + 2000.0  # far outside the image: no positives
    contact = t > rng.uniform(0.05, 0.2)
    markers = np.broadcast_to(rest, (n_frames, *rest.shape)).copy()
    normal = np.array([-np.sin(angle), np.cos(angle)])
    signed = (markers - np.stack([np.full(n_frames, cx), y0], 1)[:, None]) @ normal
    push = 8.0 * np.exp(-(signed / 30.0) ** 2) * np.sign(signed) * contact[:, None]
    markers += push[..., None] * normal + rng.normal(0.0, 1.0, markers.shape)
    markers = markers.astype(np.float32)
    labels = sim_labels(markers, line, contact)
    return markers, line.astype(np.float32), contact, labels


def write_sim(folder: str | Path, rest: np.ndarray, n_traj: int = 10, n_frames: int = 144,
              seed: int = 0) -> Path:
    """`trajectory_NNNN.npz` (even files with the vessel) + manifest.json; returns the manifest path."""
    folder = Path(folder)
    rng = np.random.default_rng(seed)
    names = []
    for i in range(n_traj):
        m, line, contact, labels = sequence(rest, n_frames, rng, vessel=i % 2 == 0)
        name = f"trajectory_{i:04d}.npz"
        save_npz(folder / name, markers=m, labels=labels, centreline_px=line, contact=contact,
                 T_BA=np.broadcast_to(np.eye(4, dtype=np.float32), (n_frames, 4, 4)),
                 kind=np.array("slide"), seed=np.array(i))
        names.append(name)
    manifest = folder / "manifest.json"
    save_json(manifest, {"trajectories": names, "synthetic": True})
    return manifest


def write_silicone(path: str | Path, rest: np.ndarray, n_videos: int = 10, n_frames: int = 16,
                   seed: int = 1) -> Path:
    rng = np.random.default_rng(seed)
    seqs = [sequence(rest, n_frames, rng) for _ in range(n_videos)]
    markers = np.stack([s[0] for s in seqs])
    labels = np.stack([s[3] for s in seqs])
    save_npz(path, markers=markers, labels=labels, found=np.ones(labels.shape, bool))
    return Path(path)


def write_meat(path: str | Path, rest: np.ndarray, n_frames=(22,) * 9 + (21,), seed: int = 2,
               n_val: int = 3) -> Path:
    """Flat `markers`/`labels` over all states cut by `trial_offsets`, and the JSON trial list beside it."""
    rng = np.random.default_rng(seed)
    seqs = [sequence(rest, n, rng) for n in n_frames]
    trials = [{"trial_id": i + 1, "split": "val" if i >= len(n_frames) - n_val else "train", "n_frames": n}
              for i, n in enumerate(n_frames)]
    save_npz(path, markers=np.concatenate([s[0] for s in seqs]),
             labels=np.concatenate([s[3] for s in seqs]).astype(np.int32),
             trial_offsets=np.cumsum([0, *n_frames]).astype(np.int64))
    save_json(Path(path).with_suffix(".json"), {"trials": trials})
    return Path(path)


def write_all(root: str | Path, rest: np.ndarray, n_traj: int = 10, n_frames: int = 144) -> dict:
    """All three datasets under `root`; -> {sim, silicone, meat} paths as the train app takes them."""
    root = Path(root)
    return {"sim": str(write_sim(root / "sim", rest, n_traj, n_frames)),
            "silicone": str(write_silicone(root / "silicone.npz", rest)),
            "meat": str(write_meat(root / "meat.npz", rest))}


if __name__ == "__main__":  # python -m palpation.graph.synthetic OUT_DIR
    import sys

    from palpation.graph.layout import rest_layout

    print(json.dumps(write_all(sys.argv[1], rest_layout("ideal")), indent=2))
