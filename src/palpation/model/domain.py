"""Which data a job's transfer options read (docs/transfer.md): the split that chooses its checkpoint
(`select_on`) and the unlabelled clips its scored set is aligned with (`align`, `align_stats`).

The two real sets are each other's "other real set": a model scored on Silicone is chosen and aligned on Meat
and the reverse. A Meat-trained model's other real set for a Silicone score is its own training set: it chooses on
the Meat val trials (never the trials it trained on) and has no other real set to align with inductively.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from palpation.graph.align import Alignment, Moments, clip_moments, fit_alignment
from palpation.graph.clips import ClipSet
from palpation.graph.sources import Sequences, load_dataset

log = logging.getLogger(__name__)
REAL_SETS = ("silicone", "meat")


def other_real_set(test_on: str) -> str:
    """The labelled real set that is not `test_on` (a real set)."""
    if test_on not in REAL_SETS:
        raise ValueError(f"the other real set of a job scored on {test_on!r} is undefined: select_on=other_real and "
                         "align_stats=other_real need a real test set (silicone or meat)")
    return REAL_SETS[1 - REAL_SETS.index(test_on)]


def half_trials(ids) -> tuple[list, list]:
    """A real set's trials in two halves, by sorted id, alternating: (the selection half, the method half). With
    select_on=other_real_half the first chooses a run's checkpoint, and the second is left to score the method
    (the transfer table's cross_real rule), so no trial does both."""
    ids = sorted(ids)
    return ids[0::2], ids[1::2]


def is_partner(config_name: str) -> bool:
    """A run scoring the other real set only for the cross_real rule: also_test's '<config>.on_<set>'."""
    return ".on_" in config_name


def partner_name(config_name: str, other: str) -> str:
    return f"{config_name}.on_{other}"


def selection_name(job) -> str:
    """The set that chooses `job`'s checkpoint: '<set> val', '<set> all' (the other real set, whole) or '<set> half'
    (its selection half, half_trials)."""
    if job.train.select_on == "val":
        return f"{job.train_on} val"
    other = other_real_set(job.test_on)
    if other == job.train_on:
        return f"{other} val"
    return f"{other} half" if job.train.select_on == "other_real_half" else f"{other} all"


def selection_sequences(job) -> Sequences:
    """The sequences `select_on` names (checkpoint, early stopping, a val calibration)."""
    name, split = selection_name(job).split(" ")
    seqs = load_dataset(name, job.data[name], "val" if split == "val" else "test")
    if split == "half":
        keep = set(half_trials(seqs.ids)[0])
        idx = [i for i, t in enumerate(seqs.ids) if t in keep]
        seqs = replace(seqs, ids=[seqs.ids[i] for i in idx], markers=[seqs.markers[i] for i in idx],
                       labels=[seqs.labels[i] for i in idx])
    return seqs


def check_selection(jobs) -> None:
    """Refuse jobs sharing one training (the first job's checkpoint split) when one is scored on that split's set
    (the training set's own test split aside: Sim val vs Sim test), unless the split is a half and the job a
    cross_real partner (is_partner: the table reads only the other half of its scores)."""
    chosen_on, split = selection_name(jobs[0]).split(" ")
    for job in jobs:
        if split == "half" and is_partner(job.config_name):
            continue
        if chosen_on == job.test_on != job.train_on:
            raise ValueError(f"{job.config_name}: select_on={job.train.select_on} chooses the checkpoint on "
                             f"{selection_name(jobs[0])}, the set it is scored on; score that set with separate runs")


def alignment(job, train: ClipSet, test: ClipSet, rest: np.ndarray, topo, source: Moments | None = None) \
        -> Alignment | None:
    """The feature alignment of `job`'s test clips, None when `align` is off. `source`: the training clips'
    moments computed already (several test sets of one training)."""
    cfg = job.train
    if cfg.align == "none":
        return None
    if cfg.align_stats == "other_real":
        other = other_real_set(job.test_on)
        if other == job.train_on:
            raise ValueError(f"{job.config_name}: align_stats=other_real has no other real set (the other one, "
                             f"{other}, is the training set); use test_set or test_sequence (transductive) or "
                             "align=none")
        target = ClipSet(load_dataset(other, job.data[other], "test"), job.clip_len, rest)
    else:
        target = test
    if source is None:
        source = clip_moments(train, rest, topo, cfg.remove_common_motion)
    out = fit_alignment(source, target, rest, topo, cfg.align, cfg.align_stats, cfg.remove_common_motion)
    log.info("%s: %s alignment of the %s clips from %s (%d map(s)%s)", job.config_name, cfg.align, job.test_on,
             cfg.align_stats, len(out.maps), ", transductive" if out.transductive else "")
    return out
