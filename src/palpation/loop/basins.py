"""A start in the camera's best other basin for the local finish (issue 13: contact + camera).

The camera acts through the nearest-node binding of S^-1(template) (twin.markers.CameraBinding), so its
objective is rough in the principal point, and a search and its local finish stay in the basin their
starts are in: in the 60-run H100 self-test three contact + camera runs ended with the right effects, the
camera in a wrong basin and the residual flagged unexplained (reduced CPU run: dx 13.4 px against 0.6).
The other basins are cheap to scan, because for a given binding the camera is exactly linear in the
displacement (markers = anchor + A (m - m_rest), A = f R(psi)) and jobs that differ only in the camera share
one simulated env. For each principal point of a grid (the nominal step over the search bounds), at the
current f and rotation:
* one projection gives the displacement as seen at the current A, once the anchor (the rest markers, the
  same for every camera) is known: from two projections at the current point, at f and f (1 + EPS) (the
  same binding);
* the similarity A' that best maps that displacement onto the measured one over the fitted states is a
  closed-form least-squares (Procrustes) fit, and its residual ranks the grid point.
The best grid point, A' composed with the current A, is one more start of the local finish (loop.polish,
whose best chain wins by the fitted MAE). Only a try that adds the camera gets it (refit.finish's
`basins`); one twin call per such finish, the search's best params' envs (n_fit per problem) and one binding
per grid point (7 x 7 at the nominal 20 px over +-60 px: ~70 ms each on this loaded CPU).

The binding is S^-1(template), so it moves with the rotation as much as with the principal point (5 deg turn
a rim marker 26 px): a grid at the current rotation ranks its points through the wrong binding when the
rotation is far off, and the closed form's A' cannot repair that (dev seed 1, contact + camera at the true
physics, rotation -4.7 deg: the grid's start at -0.9 deg, its LM chain stuck at 0.90 px, the truth at 0.24).
With `rotation` the rotation is a grid axis too (its nominal 5 deg over the bounds: 7 x 7 x 7 points), and
`refine` more scans (one twin call each) search 3 x 3 x 3 points at half the previous step around the best
start, through that start's own f and rotation; three halvings reach 2.5 px / 0.6 deg, the finish's
finite-difference unit (loop.polish), where the LM takes over (the same runs: starts at 0.26-0.38 px).
"""

from __future__ import annotations

from itertools import product
from typing import Mapping

import numpy as np

from palpation.loop.effects import bounds

CAM = ("cam_f_scale", "cam_rotation_deg", "cam_dx_px", "cam_dy_px")
BINDING = ("cam_dx_px", "cam_dy_px", "cam_rotation_deg")  # the grid's axes (f: the closed form only)
EPS = 1e-5  # relative f change: the binding (S^-1 of the template) moves < 0.01 px, so it is the same


def grid(name: str, limits: Mapping | None, step: float) -> np.ndarray:
    low, high = bounds(name, limits)
    return np.arange(np.ceil(low / step) * step, high + 1e-9, step)


def residual(y: np.ndarray, d: np.ndarray, a: float, b: float) -> float:
    """|y - A' d|^2 over rows, A' = [[a, -b], [b, a]]."""
    pred = np.stack([a * d[:, 0] - b * d[:, 1], b * d[:, 0] + a * d[:, 1]], axis=1)
    return float(((y - pred) ** 2).sum())


def procrustes(y: np.ndarray, d: np.ndarray) -> tuple[float, float, float]:
    """(a, b, rss) of min |y - A' d|^2 over rows, A' = [[a, -b], [b, a]] (a scaled rotation)."""
    nn = float((d ** 2).sum())
    if nn <= 0:
        return 1.0, 0.0, float((y ** 2).sum())
    a = float((d * y).sum()) / nn
    b = float((d[:, 0] * y[:, 1] - d[:, 1] * y[:, 0]).sum()) / nn
    return a, b, residual(y, d, a, b)


def _scan(todo: list, points: Mapping[str, list], simulate, limits: Mapping[str, Mapping | None]) -> dict:
    """One twin call: per problem, the best of its camera `points` (params that differ from p.params in the
    camera only) as (rss, start params), f and rotation corrected by the closed-form similarity."""
    jobs, index, anchors = [], [], {}
    for p in todo:
        fit = [t for t in p.targets if t.fit]
        # the anchor (the rest markers) does not depend on the camera: from the current point and f (1 + EPS)
        anchors[p.name] = len(jobs)
        jobs += [(t.state, p.params) for t in fit]
        jobs += [(t.state, {**p.params, "cam_f_scale": p.params["cam_f_scale"] * (1.0 + EPS)}) for t in fit]
        for params in points[p.name]:
            index.append((p, fit, params, len(jobs)))
            jobs += [(t.state, params) for t in fit]
    markers, failed = simulate(jobs)
    markers = np.asarray(markers, np.float64)
    best: dict[str, tuple] = {}
    for p, fit, params, s in index:
        m, a0 = len(fit), anchors[p.name]
        if failed[a0:a0 + 2 * m].any() or failed[s:s + m].any():
            continue
        anchor = markers[a0:a0 + m] - (markers[a0 + m:a0 + 2 * m] - markers[a0:a0 + m]) / EPS
        d = markers[s:s + m] - anchor  # A (m - m_rest) through this point's binding, this point's A
        y = np.stack([t.markers for t in fit]) - anchor
        a, b, _ = procrustes(y.reshape(-1, 2), d.reshape(-1, 2))
        lim, out = limits.get(p.name), dict(params)
        for n, v in (("cam_f_scale", params["cam_f_scale"] * float(np.hypot(a, b))),
                     ("cam_rotation_deg", params["cam_rotation_deg"] + float(np.degrees(np.arctan2(b, a))))):
            low, high = bounds(n, lim)
            out[n] = float(np.clip(v, low, high))
        # rank by the residual of the similarity actually started from (f and rotation clipped into bounds)
        s_ = out["cam_f_scale"] / params["cam_f_scale"]
        t_ = np.radians(out["cam_rotation_deg"] - params["cam_rotation_deg"])
        rss = residual(y.reshape(-1, 2), d.reshape(-1, 2), s_ * np.cos(t_), s_ * np.sin(t_))
        if p.name not in best or rss < best[p.name][0]:
            best[p.name] = (rss, out)
    return best


def _clipped(params: Mapping[str, float], lim) -> dict:
    return {**params, **{n: float(np.clip(params[n], *bounds(n, lim))) for n in BINDING}}


def camera_starts(problems: list, simulate, limits: Mapping[str, Mapping | None],
                  steps: Mapping[str, float], rotation: bool = False, refine: int = 0) -> dict[str, dict]:
    """Per problem that searches the camera: the best grid start (its params), in 1 + `refine` twin calls.
    `steps`: the grid step per binding parameter (nominal_steps). `rotation`: the rotation is a grid axis
    too, not only the closed-form correction at the current rotation; `refine`: that many more scans around
    the best start, each on a grid of half the previous step through the best start's own f and rotation."""
    todo = [p for p in problems if all(n in p.searched for n in CAM)]
    if not todo:
        return {}
    axes = BINDING if rotation else BINDING[:2]
    points = {}
    for p in todo:
        lim = limits.get(p.name)
        values = [grid(n, lim, steps[n]) for n in axes]
        points[p.name] = [{**p.params, **{n: float(v) for n, v in zip(axes, vs)}} for vs in product(*values)]
    best = _scan(todo, points, simulate, limits)
    for k in range(refine):  # a finer grid through the best start (its f and rotation are the closed form's)
        h = 0.5 ** (k + 1)
        points = {name: [_clipped({**b, **{n: b[n] + o * h * steps[n] for n, o in zip(axes, offs)}}, limits.get(name))
                         for offs in product((-1, 0, 1), repeat=len(axes))] for name, (_, b) in best.items()}
        best = {**best, **_scan([p for p in todo if p.name in points], points, simulate, limits)}
    return {name: v[1] for name, v in best.items()}


def nominal_steps(steps: Mapping[str, float]) -> dict[str, float]:
    """The grid step of the principal point and the rotation: their nominal steps (loop.method.steps over effects.py's)."""
    from palpation.loop.effects import EFFECTS
    moves = {n: amt for d in EFFECTS["camera"].dofs for n, _, amt in d.moves}
    return {n: float(steps.get(n, moves[n])) for n in BINDING}
