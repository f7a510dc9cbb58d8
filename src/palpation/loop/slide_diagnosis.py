"""What the slides' marker motion is made of (issue 12; docs/loop.md "Slides", diagnosis).

Per frame, the motion of the found markers (each about its median over the trial, loop.slides.motion) is
split into a common translation of the whole field, what a per-frame affine map of the rest positions adds,
and what is left; plus the frame-to-frame jitter (second difference of the raw positions, a noise scale).
For a replay's markers (C, T, F, 127, 2) it also gives the error of that common translation and of the rest.

    python -m palpation.loop.slide_diagnosis [--sequences results/data/silicone/silicone_sequences]

A developer diagnostic, outside the results DAG: argparse, like loop.judge_budget.
"""

from __future__ import annotations

import argparse

import numpy as np

from palpation.loop.slides import motion


def common_translation(m: np.ndarray, found: np.ndarray) -> np.ndarray:
    """(..., T, F, 2): the mean over found markers of each frame's motion m (..., T, F, 127, 2)."""
    w = np.broadcast_to(found, m.shape[:-1])[..., None]
    return (m * w).sum(-2) / np.maximum(w.sum(-2), 1)


def decomposition(markers: np.ndarray, found: np.ndarray, rest: np.ndarray) -> dict[str, float]:
    """Mean |motion| px per marker and frame (markers (T, F, 127, 2)): total, after the common translation,
    after a per-frame affine map of the rest positions; the jitter; the lag-1 autocorrelation of the motion."""
    m = motion(markers)
    c = common_translation(m, found)
    after_t = m - c[..., None, :]
    x = rest - rest.mean(axis=0)
    after_a = np.zeros_like(m)
    for t in range(m.shape[0]):
        for k in range(m.shape[1]):
            w = found[t, k]
            xc = x - x[w].mean(axis=0)
            a, *_ = np.linalg.lstsq(xc[w], after_t[t, k][w], rcond=None)
            after_a[t, k] = after_t[t, k] - xc @ a
    both = found[:, 1:] & found[:, :-1]
    lag1 = (m[:, 1:] * m[:, :-1]).sum(-1)[both].mean() / (m * m).sum(-1)[found].mean()
    jitter = np.linalg.norm(markers[:, 1:-1] - 0.5 * (markers[:, :-2] + markers[:, 2:]), axis=-1)
    return {"motion_px": float(np.linalg.norm(m, axis=-1)[found].mean()),
            "common_translation_px": float(np.linalg.norm(c, axis=-1).mean()),
            "after_translation_px": float(np.linalg.norm(after_t, axis=-1)[found].mean()),
            "after_affine_px": float(np.linalg.norm(after_a, axis=-1)[found].mean()),
            "jitter_px": float(jitter[found[:, 1:-1]].mean()), "lag1_autocorrelation": float(lag1)}


def replay_errors(sim: np.ndarray, markers: np.ndarray, found: np.ndarray) -> dict[str, np.ndarray]:
    """Per candidate (sim (C, T, F, 127, 2)): |common translation| of the sim, its error against the real one,
    and the error of the rest of the motion (px means)."""
    ms, mr = motion(sim), motion(markers)
    cs, cr = common_translation(ms, found), common_translation(mr, found)
    rest_err = np.linalg.norm((ms - cs[..., None, :]) - (mr - cr[..., None, :]), axis=-1)
    f = np.broadcast_to(found, rest_err.shape)
    return {"sim_common_px": np.linalg.norm(cs, axis=-1).mean(axis=(-1, -2)),
            "common_error_px": np.linalg.norm(cs - cr, axis=-1).mean(axis=(-1, -2)),
            "rest_error_px": np.where(f, rest_err, 0).sum(axis=(-1, -2, -3)) / f.sum(axis=(-1, -2, -3))}


def main() -> None:
    from palpation.measured_sequences import load_sequence_set

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sequences", default="results/data/silicone/silicone_sequences")
    s = load_sequence_set(p.parse_args().sequences)
    for key, value in decomposition(s.markers.astype(np.float64), s.found, s.rest.astype(np.float64)).items():
        print(f"{key:24s} {value:.3f}")


if __name__ == "__main__":
    main()
