"""What the loop reads: the interaction states of any measured set in the generic format, checked.

The loop knows only the file: states with a trajectory kind, depth and angle, and their ordered
markers. A set built in memory is checked as strictly as a loaded one (marker count, finite
coordinates, known trajectories), and the loop's own choices (held-out states, state subset) are
checked against it, all before anything is simulated.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from palpation.loop.simulate import State
from palpation.markers.lattice import N_MARKERS
from palpation.measured import TRAJECTORIES, MeasuredSet
from palpation.twin.trajectory import KINDS

TWIST_Z_ANGLES = ("reference", "filename")


@dataclass(frozen=True)
class Target:
    state: State
    markers: np.ndarray  # (127, 2) measured pixels
    fit: bool  # False = held out: scored, never fitted

    @property
    def name(self) -> str:
        return self.state.name


def check_measured(mset: MeasuredSet, source: str) -> None:
    """Shapes, finiteness and trajectory kinds of a set, whether loaded or built in memory."""
    m = np.asarray(mset.markers)
    if m.ndim != 3 or m.shape[1:] != (N_MARKERS, 2):
        raise ValueError(f"{source}: markers have shape {m.shape}, expected (S, {N_MARKERS}, 2); order "
                         "detections onto the 127-marker template (palpation.markers.order)")
    if len(mset.states) != len(m):
        raise ValueError(f"{source}: {len(mset.states)} states but {len(m)} marker rows; they must match")
    if not np.all(np.isfinite(m)):
        bad = sorted({mset.states[i].name for i in np.argwhere(~np.isfinite(m))[:, 0]})
        raise ValueError(f"{source}: NaN/inf marker coordinates in state(s) {bad}; fill missing markers "
                         "(found=False) instead of storing NaN")
    for s in mset.states:
        if s.trajectory not in TRAJECTORIES:
            raise ValueError(f"{source}: state '{s.name}' has unknown trajectory kind '{s.trajectory}'; "
                             f"use one of {list(TRAJECTORIES)}")


def _select(names: Sequence[str], states, what: str, source: str) -> set[str]:
    """Entries may be state names or trajectory kinds; each must match something."""
    out = set()
    for entry in names:
        hit = {s.name for s in states if entry in (s.name, s.trajectory)}
        if not hit:
            raise ValueError(f"{what}: '{entry}' is neither a state name nor a trajectory kind of {source} "
                             f"(states: {[s.name for s in states]})")
        out |= hit
    return out


def load_targets(mset: MeasuredSet, source: str, holdout: Sequence[str] = (),
                 states: Sequence[str] | None = None, twist_z_angle: str = "reference") -> list[Target]:
    """The interaction states to reproduce (rest states carry no motion), fitted or held out."""
    check_measured(mset, source)
    if twist_z_angle not in TWIST_Z_ANGLES:
        raise ValueError(f"loop.twist_z_angle must be one of {TWIST_Z_ANGLES}, got '{twist_z_angle}'")
    moving = [s for s in mset.states if s.trajectory in KINDS]
    if not moving:
        raise ValueError(f"{source}: no interaction state (trajectory in {list(KINDS)}); the loop needs at "
                         "least one pressed, twisted or slid state")
    keep = _select(states, moving, "loop.states", source) if states else {s.name for s in moving}
    held = _select(holdout, moving, "loop.holdout", source) & keep
    if not keep - held:
        raise ValueError(f"loop.holdout={list(holdout)} leaves no state of {source} to fit")
    out = []
    for i, s in enumerate(mset.states):
        if s.name not in keep:
            continue
        angle = s.angle_deg
        if s.trajectory == "twist_z" and twist_z_angle == "reference":
            angle = None  # the reference simulated 30 deg, whatever the file name says (quirk 5)
        state = State(s.name, s.trajectory, s.depth_mm, angle)
        out.append(Target(state, np.asarray(mset.markers[i], np.float64), s.name not in held))
    return out


def set_key(mset: MeasuredSet) -> str:
    """A short content hash: study names of one set never mix with another's."""
    h = hashlib.sha1(np.ascontiguousarray(mset.markers, np.float32).tobytes())
    h.update(repr([(s.name, s.trajectory, s.depth_mm, s.angle_deg) for s in mset.states]).encode())
    return h.hexdigest()[:10]
