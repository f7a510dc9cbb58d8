"""The residual of one state, simulated - real markers, split into named modes with energy shares.

Modes over the marker positions q = x - c about the sensor centre c = (1040, 584):
* translation (1, 0), (0, 1);
* rotation about c: (-q_y, q_x);
* isotropic radial (scale): (q_x, q_y);
* anisotropic stretch/shear (traceless symmetric): (q_x, -q_y), (q_y, q_x);
* local: what none of the above carries (the contact-region field).
The fields are Gram-Schmidt orthonormalised in this order over the stacked 2 x 127 coordinates, so
the shares of the residual energy sum to 1 exactly. The interpretable amplitudes (px, deg, %, the
stretch axis) come from the plain least-squares fit on the non-orthogonalised fields.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from palpation.camera import DEFAULT_CAMERA
from palpation.twin.trajectory import BASE_ROTATION

MODES = ("translation", "rotation", "radial", "stretch_shear", "local")
CENTRE_PX = DEFAULT_CAMERA.centre
CENTRAL_RADIUS_PX = 190.0  # half the image circle: where a flat phantom's contact patch shows


def mode_fields(points_px: np.ndarray, centre: np.ndarray = CENTRE_PX) -> tuple[np.ndarray, list[str]]:
    """(2M, 6) non-orthogonal mode fields at the markers and the mode of each column."""
    q = np.asarray(points_px, np.float64) - centre
    qx, qy, one, zero = q[:, 0], q[:, 1], np.ones(len(q)), np.zeros(len(q))
    cols = [(one, zero), (zero, one), (-qy, qx), (qx, qy), (qx, -qy), (qy, qx)]
    fields = np.stack([np.stack(c, axis=1).reshape(-1) for c in cols], axis=1)
    return fields, ["translation", "translation", "rotation", "radial", "stretch_shear", "stretch_shear"]


def image_direction_deg(heading_deg: float, rotation: Rotation = BASE_ROTATION) -> float:
    """Image angle (deg; 0 = +u right, 90 = +v down) of a world motion at `heading_deg` in the xy plane."""
    d_A = np.array([np.cos(np.radians(heading_deg)), np.sin(np.radians(heading_deg)), 0.0])
    d_B = rotation.inv().apply(d_A)  # camera E has the body axes: u along +x_B, v along +y_B
    return float(np.degrees(np.arctan2(d_B[1], d_B[0])))


@dataclass
class Decomposition:
    name: str
    mae_px: float
    energy_px2: float  # sum of squared residual components
    shares: dict[str, float]  # per MODE, sums to 1
    translation_px: tuple[float, float]
    rotation_deg: float
    scale_pct: float
    stretch_pct: float  # magnitude of the traceless stretch (% strain)
    stretch_axis_deg: float  # image angle of the stretching axis, in (-90, 90]
    axis_vs_slide_deg: float | None  # |axis - slide direction| folded into [0, 90]; slides only
    local_central_fraction: float  # share of the local energy on markers within CENTRAL_RADIUS_PX

    def row(self) -> dict:
        out = asdict(self)
        shares = out.pop("shares")
        return {**out, **{f"share_{k}": v for k, v in shares.items()}}


def decompose(sim_px: np.ndarray, real_px: np.ndarray, name: str = "", slide_image_deg: float | None = None,
              centre: np.ndarray = CENTRE_PX) -> Decomposition:
    """Split sim - real at the real marker positions into MODES (shares of the residual energy)."""
    real = np.asarray(real_px, np.float64)
    r = (np.asarray(sim_px, np.float64) - real).reshape(-1)
    if not np.all(np.isfinite(r)):
        raise ValueError(f"residual of state '{name}': simulated or measured markers are not finite")
    fields, labels = mode_fields(real, centre)
    basis, _ = np.linalg.qr(fields)  # Gram-Schmidt in column order
    coef = basis.T @ r
    energy = float(r @ r)
    shares = {m: 0.0 for m in MODES}
    for c, label in zip(coef, labels):
        shares[label] += float(c * c) / energy if energy > 0 else 0.0
    local = r - basis @ coef
    shares["local"] = float(local @ local) / energy if energy > 0 else 0.0
    b, *_ = np.linalg.lstsq(fields, r, rcond=None)
    axis = 0.5 * np.degrees(np.arctan2(b[5], b[4]))
    vs = None
    if slide_image_deg is not None:
        d = abs((axis - slide_image_deg + 90.0) % 180.0 - 90.0)
        vs = float(d)
    loc = local.reshape(-1, 2)
    central = np.linalg.norm(real - centre, axis=1) < CENTRAL_RADIUS_PX
    loc_e = (loc ** 2).sum(axis=1)
    return Decomposition(
        name=name, mae_px=float(np.mean(np.linalg.norm(r.reshape(-1, 2), axis=1))), energy_px2=energy,
        shares=shares, translation_px=(float(b[0]), float(b[1])), rotation_deg=float(np.degrees(b[2])),
        scale_pct=float(100 * b[3]), stretch_pct=float(100 * np.hypot(b[4], b[5])),
        stretch_axis_deg=float(axis),
        axis_vs_slide_deg=vs,
        local_central_fraction=float(loc_e[central].sum() / loc_e.sum()) if loc_e.sum() > 0 else 0.0)
