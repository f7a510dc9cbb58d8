"""What the robust recipe's training batches look like against the Sim validation split (issue 15), no training.

    python -m palpation.model.diagnose --sim results/sim/dataset/manifest.json [--clips 256] [--seed 0]

Every robust Sim seed of the paper profile keeps its epoch-0 checkpoint: Sim val AP falls after the first epoch.
This measures the candidate causes that need no training, on the Sim train and val splits only:
  * rotation: the offset a `consistent` rotation adds to a node (its rotated position minus its rest site plus the
    rotated displacement, i.e. `consistent` minus `lattice`), against the vessel's displacement signal in val clips
    (|marker - rest| of positive and of negative markers at the central frame);
  * normalisation: each scaled feature column of val clips and of augmented training batches (robust; with
    lattice rotation; without jitter), z-scored with the robust statistics (from the training clips): mean and std per column; a
    val set that saw the same normalisation has mean ~0, std ~1 like the training batches;
  * labels: the positive share of training and val markers (the focal α).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from palpation.graph.clips import ClipSet
from palpation.graph.edges import clip_topology, spatial_edges
from palpation.graph.features import clip_features
from palpation.graph.layout import rest_layout
from palpation.graph.normalise import N_SCALED
from palpation.graph.sources import load_dataset
from palpation.model.config import TrainConfig
from palpation.model.train import norm_stats, training_batch

COLUMNS = {"node": ("x", "y", "rest dist"), "spatial": ("dist", "dx", "dy"), "temporal": ("dist", "dx", "dy")}


def rotation_offsets(train: ClipSet, idx: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """|consistent - lattice| per node and frame of clips `idx`, each rotated by a random non-zero step (px)."""
    rot = rng.integers(1, 6, size=len(idx))
    mc, _ = train.gather(idx, rot, consistent=True)
    ml, _ = train.gather(idx, rot, lattice=True)
    return np.linalg.norm(mc - ml, axis=-1).ravel()


def displacement_signal(val: ClipSet, rest: np.ndarray) -> dict:
    """Median |marker - rest| (px) at the central frame of every val clip, positive and negative markers."""
    m, lab = val.gather(np.arange(len(val)))
    k = val.clip_len // 2
    d = np.linalg.norm(m[:, k] - rest, axis=-1)
    pos = lab[:, k].astype(bool)
    return {"positive_px": float(np.median(d[pos])) if pos.any() else float("nan"),
            "negative_px": float(np.median(d[~pos])), "positive_share": float(pos.mean())}


def scaled_columns(feats, stats) -> dict:
    """Mean and std of every z-scored column (COLUMNS) of `feats` under `stats`."""
    z = stats.apply(feats)
    out = {}
    for group, arr in (("node", z.x), ("spatial", z.spatial), ("temporal", z.temporal)):
        cols = arr[..., :N_SCALED].reshape(-1, N_SCALED)
        for j, name in enumerate(COLUMNS[group]):
            out[f"{group} {name}"] = (float(cols[:, j].mean()), float(cols[:, j].std()))
    return out


def diagnose(sim: str, n_clips: int = 256, seed: int = 0, rest_name: str = "template") -> dict:
    rest = rest_layout(rest_name)
    topo = clip_topology(spatial_edges(rest), 5)
    train = ClipSet(load_dataset("sim", sim, "train"), 5, rest)
    val = ClipSet(load_dataset("sim", sim, "val"), 5, rest)
    rng = np.random.default_rng(seed)
    idx = rng.choice(len(train), size=min(n_clips, len(train)), replace=False)
    robust = TrainConfig(norm_stats="full", rotation="consistent", jitter_px=0.2, marker_dropout=0.01,
                         displacement_scale=0.3)
    stats = norm_stats(train, rest, topo, robust, np.random.default_rng(seed))
    val_m, val_lab = val.gather(np.arange(len(val)))
    feats = {"val": clip_features(val_m, rest, topo)}
    for name, cfg in (("train robust", robust), ("train lattice", replace(robust, rotation="lattice")),
                      ("train no jitter", replace(robust, jitter_px=0.0))):
        m, _ = training_batch(train, idx, cfg, np.random.default_rng(seed))
        feats[name] = clip_features(m, rest, topo)
    step = np.linalg.norm(np.diff(val_m, axis=1), axis=-1)  # frame-to-frame motion of every marker
    off = rotation_offsets(train, idx, rng)
    return {"clips": {"train": len(train), "val": len(val), "sampled": len(idx)},
            "rotation_offset_px": {q: float(np.percentile(off, p)) for q, p in (("median", 50), ("p90", 90),
                                                                               ("max", 100))},
            "val_signal": displacement_signal(val, rest), "train_positive_share": 1.0 - stats.alpha,
            "val_step_px": {q: float(np.percentile(step, p)) for q, p in (("p25", 25), ("median", 50), ("p75", 75))},
            "val_positive_share_all_frames": float(val_lab.mean()),
            "columns": {k: scaled_columns(v, stats) for k, v in feats.items()}}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sim", required=True, help="the Sim set's manifest.json")
    ap.add_argument("--clips", type=int, default=256, help="training clips sampled for the batches")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    r = diagnose(a.sim, a.clips, a.seed)
    print(f"clips {r['clips']}; positive share: train {r['train_positive_share']:.4f}, val (all frames) "
          f"{r['val_positive_share_all_frames']:.4f}")
    o, s = r["rotation_offset_px"], r["val_signal"]
    print(f"consistent rotation's offset per node: median {o['median']:.2f} px, p90 {o['p90']:.2f}, max {o['max']:.2f}; "
          f"val |marker - rest| at the central frame: positives {s['positive_px']:.2f} px, negatives "
          f"{s['negative_px']:.2f} px")
    st = r["val_step_px"]
    print(f"val frame-to-frame motion per marker (one clip step): p25 {st['p25']:.2f} px, median {st['median']:.2f}, "
          f"p75 {st['p75']:.2f}")
    names = list(next(iter(r["columns"].values())))
    print("z-scored column: " + " | ".join(f"{k} mean/std" for k in r["columns"]))
    for n in names:
        print(f"  {n:16s} " + " | ".join(f"{v[n][0]:+.3f} / {v[n][1]:.3f}" for v in r["columns"].values()))


if __name__ == "__main__":
    main()
