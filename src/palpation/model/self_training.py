"""The training set of a self-training run (`recipe.pseudo`, docs/transfer.md): the training domain's clips plus
a real set's unlabelled clips, pseudo-labelled where the teacher runs' seeds agree (model.pseudo_labels).

Whose clips: `other_real`, the labelled real set other than the scored one (inductive: a model scored on Silicone
self-trains on Meat's inputs), or `test_set`, the scored set's own inputs (transductive). Either way only the set's
markers are read from its file: its labels are replaced by the pseudo-label codes (graph.pseudo) before any clip
is built, and the teachers' scores give their probabilities alone.

The teachers: `recipe.pseudo_from` is one teacher run folder (`<config>/L<n>`, holding seed<s>/scores.npz and
metrics.json), or a method's root above such folders, where the one configuration that scored the set is taken
(preferring one trained on the student's training set). Their scores must be of the very clips the student
builds (same set, clip length and windows), at least two seeds of them.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from palpation.graph.clips import ClipSet
from palpation.graph.pseudo import ClipSets, pseudo_codes
from palpation.graph.sources import load_dataset
from palpation.metrics.scores import load_scores
from palpation.model.domain import REAL_SETS, other_real_set
from palpation.readers import read_json
from palpation.model.pseudo_labels import ensemble_pseudo_labels

log = logging.getLogger(__name__)
FIX = "train the teacher method first (docs/transfer.md, the two-stage commands) or fix recipe.pseudo_from"


def pseudo_set(job) -> str:
    """The real set whose unlabelled clips `job` self-trains on."""
    cfg = job.train
    if cfg.pseudo == "test_set":
        if job.test_on not in REAL_SETS or job.test_on == job.train_on:
            raise ValueError(f"{job.config_name}: recipe.pseudo=test_set needs a real scored set other than the "
                             f"training set (got test_on={job.test_on}, train_on={job.train_on})")
        return job.test_on
    other = other_real_set(job.test_on)
    if other == job.train_on:
        raise ValueError(f"{job.config_name}: recipe.pseudo=other_real has no unlabelled set (the other real set, "
                         f"{other}, is the training set); use recipe.pseudo=test_set (transductive) or none")
    return other


def _seed_dirs(folder: Path) -> list[Path]:
    return sorted((p for p in folder.glob("seed*") if p.name[4:].isdigit() and (p / "scores.npz").is_file()),
                  key=lambda p: int(p.name[4:]))


def teacher_runs(root: str | Path, set_name: str, train_on: str, clip_len: int) -> list[Path]:
    """The teacher seeds' run folders that scored `set_name` at `clip_len`, under `root` (see the module doc)."""
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"recipe.pseudo_from={root}: no such folder; {FIX}")
    folders = [root] if _seed_dirs(root) else sorted(root.glob(f"*/L{clip_len}"))
    found = {}
    for folder in folders:
        seeds = _seed_dirs(folder)
        meta = [read_json(s / "metrics.json", FIX, "teacher run", kind=dict,
                          keys=("test_on", "train_on", "clip_len")) for s in seeds]
        if seeds and all(m["test_on"] == set_name and m["clip_len"] == clip_len for m in meta):
            found[folder] = (seeds, {m["train_on"] for m in meta})
    if len(found) > 1:
        same = {f: v for f, v in found.items() if v[1] == {train_on}}
        found = same if len(same) == 1 else found
    if len(found) != 1:
        raise ValueError(f"recipe.pseudo_from={root}: need one teacher folder of runs scored on {set_name} at "
                         f"L={clip_len}, found {sorted(map(str, found)) or 'none'}; point pseudo_from at one "
                         f"<config>/L{clip_len} folder. {FIX}")
    seeds = next(iter(found.values()))[0]
    if len(seeds) < 2:
        raise ValueError(f"{seeds[0].parent}: pseudo-labels need the scores of at least 2 teacher seeds; {FIX}")
    return seeds


def pseudo_clips(job, rest: np.ndarray) -> tuple[ClipSet, dict]:
    """The pseudo-labelled clips of `job`'s pseudo set and what metrics.json records of them."""
    cfg, name = job.train, pseudo_set(job)
    seqs = load_dataset(name, job.data[name], "test")
    clips = ClipSet(seqs, job.clip_len, rest)
    runs = teacher_runs(cfg.pseudo_from, name, job.train_on, job.clip_len)
    scores = [load_scores(r / "scores.npz") for r in runs]
    seq, frame = clips.central_frames()
    if not (np.array_equal(scores[0].sequence, seq) and np.array_equal(scores[0].frame, frame)):
        raise ValueError(f"{runs[0]}: its scores are not of the {len(seq)} clips of {name} at L={job.clip_len} "
                         f"(sequence, frame ids differ); train the teachers on the same {name} file and clip_len")
    labels, keep = ensemble_pseudo_labels(scores, min_agree=cfg.pseudo_min_agree, margin=cfg.pseudo_margin)
    codes = pseudo_codes(labels, keep).reshape(len(seq), -1)
    per_seq = [np.full(m.shape[:2], -1, np.int8) for m in seqs.markers]  # frames no teacher scored: no label
    for s, f, c in zip(seq, frame, codes):
        per_seq[s][f] = c
    seqs.labels = per_seq  # the set's own labels are dropped here, before any clip is built
    if not keep.any():
        raise ValueError(f"{runs[0].parent}: the {len(runs)} teacher seeds agree on no marker of {name} (min_agree "
                         f"{cfg.pseudo_min_agree}, margin {cfg.pseudo_margin}): nothing to self-train on; use more "
                         "teacher seeds or a laxer recipe.pseudo_min_agree / pseudo_margin")
    record = {"set": name, "transductive": name == job.test_on, "from": str(runs[0].parent),
              "teacher_seeds": [int(r.name[4:]) for r in runs], "min_agree": cfg.pseudo_min_agree,
              "margin": cfg.pseudo_margin, "weight": cfg.pseudo_weight, "clips": len(clips),
              "markers_scored": int(keep.size), "markers_kept": int(keep.sum()),
              "kept_positive": int(labels[keep].sum())}
    log.info("%s: self-training on %d %s clips, %d of %d scored markers pseudo-labelled (%d positive) by %d "
             "teacher seeds%s", job.config_name, len(clips), name, record["markers_kept"], keep.size,
             record["kept_positive"], len(runs), ", transductive" if record["transductive"] else "")
    return clips, record


def with_pseudo_clips(job, train: ClipSet, rest: np.ndarray) -> tuple[ClipSet | ClipSets, dict | None]:
    """`train` plus the pseudo-labelled clips when `recipe.pseudo` is on; (train, None) when off."""
    if job.train.pseudo == "none":
        return train, None
    clips, record = pseudo_clips(job, rest)
    return ClipSets([train, clips]), record
