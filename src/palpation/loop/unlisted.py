"""Effects outside the loop's candidate list: the self-tests' library of what the twin cannot make.

Each is a transform of one run's simulated markers, all states at once ((S, 127, 2) -> same), applied before
the detector noise, with a strength in its own nominal steps and a default range for the generative draw
(loop.selftest.generative). The candidates (loop.effects) are: E, surface contact (k_s), friction (k_t, mu), the camera
(an image similarity S = c + sR(u - c) + d; as the twin applies it, markers = rest + sR(m - m_rest) through a
re-binding, so it scales and rotates *displacements* isotropically and never moves the rest image), the mount
(a rigid pose offset), viscous damping (alpha), a layered skin (a stiffer shell of uniform ratio) and
marker_anchor (one fixed field, template - bound rest, times a scalar). The twin's gel is a homogeneous,
isotropic stable Neo-Hookean solid driven by displacements, so E alone changes the marker field only through its
ratio to the contact stiffness and the damping, never its dependence on the amplitude. Why none of them can
express each outside effect:

* image_distortion (optical): barrel distortion about the principal point, x(1 + k r^2). A static field of the
  image position, the same in every state: the camera cannot move the rest image, a similarity is linear in
  position, and the anchor's field is a fixed one.
* tangential_distortion (optical): decentering distortion (Brown-Conrady p1, p2; a tilted or decentred lens),
  quadratic in position and not radially symmetric: a similarity (linear) cannot fit it, nor can a principal
  point shift of a radial model; static in every state, as above.
* marker_defect (sensor): a patch of 7 markers displaced rigidly in every state (a torn or re-glued skin patch).
  Every candidate acts smoothly through the gel or the projection; the anchor's field is fixed.
* strain_stiffening (physical): each marker's displacement from rest shrinks with its own magnitude,
  u' = u (1 - c (|u| / u_max)^2), the lowest order of a gel that stiffens at large strain beyond Neo-Hookean (a
  cubic term in the force). E scales the stiffness at every strain alike, the shell with depth, damping with
  rate, contact and friction are boundary conditions, and the camera scales all displacements by one factor:
  none depends on the displacement's own size.
* anisotropic_gel (physical): displacements from rest scaled by (1 + c) along an in-plane axis and (1 - c)
  across it (a gel stiffer in one direction, e.g. a stretched cast). Every physical candidate is isotropic in
  the sensor plane; the camera's sR is isotropic too, and the mount moves the whole sensor rigidly.

The two physical kinds act on displacements from the run's own rest markers (`rest`: the twin that made the data,
at rest; twin_rest below). Their coefficient c is set so that the largest displacement of the set moves by
`strength` x STIFFEN_PX / ANISO_PX px (c capped: MAX_STIFFEN, MAX_ANISO): without contact the twin's displacements
are a few px, with it tens, and a fixed c would be invisible in the first case and huge in the second. With a few
px the cap binds, and a stiffening is then a weak effect (the summary gives the `unexplained` share per kind).
Strength ranges start where an image similarity fitted to the change leaves ~3x the 0.2 px noise (the test's
known answer, on a contact-sized press). Whether the loop
also cannot *absorb* them through its fit is what the self-test measures (outside runs: `unexplained`, and no
physical effect named beyond the in-list truth); tests/loop/selftest/test_generative.py checks that no image
similarity absorbs any of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from palpation.loop.residual import CENTRE_PX

UNLISTED_PREFIX = "unlisted:"
DISTORTION_RADIUS_PX = 400.0  # ~ the image circle's radius
DISTORTION_K = 0.02  # barrel coefficient per nominal step: 8 px at r = 400 px per step
TANGENTIAL_K = 0.006  # decentering (p1, p2) magnitude per nominal step: ~2.5 px at r = 300 px per step
DEFECT_MARKERS = 7  # a patch: a marker and its 6 neighbours
DEFECT_PX = 4.0  # patch displacement per nominal step
STIFFEN_PX = 4.0  # strain_stiffening: change of the set's largest displacement per step
MAX_STIFFEN = 1.0 / 3.0  # c at most: |u'| = |u| (1 - c x^2) stays monotone in |u| (x <= 1)
ANISO_PX = 2.0  # anisotropic_gel: change of the set's largest displacement per step
MAX_ANISO = 0.5  # c at most: both axes' scales (1 -+ c) stay positive


@dataclass(frozen=True)
class Unlisted:
    name: str
    kind: str  # optical | sensor | physical
    transform: Callable  # (markers (S, 127, 2), strength, rng, rest (127, 2) | None) -> markers
    strength: tuple[float, float]  # default range of the generative draw, nominal steps (log-uniform)

    def __call__(self, m: np.ndarray, s: float, rng: np.random.Generator, rest: np.ndarray | None = None
                 ) -> np.ndarray:
        return self.transform(np.asarray(m, np.float64), float(s), rng, rest)


def _distortion(m, s, rng, rest):
    q = m - CENTRE_PX
    r2 = (q ** 2).sum(axis=-1, keepdims=True) / DISTORTION_RADIUS_PX ** 2
    return CENTRE_PX + q * (1.0 + DISTORTION_K * s * r2)


def _tangential(m, s, rng, rest):
    phi = rng.uniform(0, 2 * np.pi)  # the decentering's direction
    p1, p2 = TANGENTIAL_K * s * np.cos(phi), TANGENTIAL_K * s * np.sin(phi)
    q = (m - CENTRE_PX) / DISTORTION_RADIUS_PX
    x, y = q[..., 0], q[..., 1]
    r2 = x ** 2 + y ** 2
    d = np.stack([2 * p1 * x * y + p2 * (r2 + 2 * x ** 2), p1 * (r2 + 2 * y ** 2) + 2 * p2 * x * y], axis=-1)
    return m + DISTORTION_RADIUS_PX * d


def _defect(m, s, rng, rest):
    rest = m[0]  # the patch is picked on the first state (the fixed self-test's draws stay as they were)
    centre = rng.integers(len(rest))
    patch = np.argsort(np.linalg.norm(rest - rest[centre], axis=1))[:DEFECT_MARKERS]
    angle = rng.uniform(0, 2 * np.pi)
    out = m.copy()
    out[:, patch] += DEFECT_PX * s * np.array([np.cos(angle), np.sin(angle)])
    return out


def _displacements(m, s, rest, name: str, px: float, cap: float) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(u = m - rest, |u|, u_max, c): c moves the largest displacement by s * px px (c <= cap)."""
    if rest is None:
        raise ValueError(f"unlisted:{name} acts on displacements from the twin's rest markers; pass `rest` "
                         "(loop.generative.twin_rest)")
    u = m - np.asarray(rest, np.float64)
    mag = np.linalg.norm(u, axis=-1, keepdims=True)
    u_max = float(mag.max())
    return u, mag, u_max, min(cap, s * px / u_max) if u_max > 0 else 0.0


def _stiffening(m, s, rng, rest):
    u, mag, u_max, c = _displacements(m, s, rest, "strain_stiffening", STIFFEN_PX, MAX_STIFFEN)
    return m.copy() if u_max == 0 else rest + u * (1.0 - c * (mag / u_max) ** 2)


def _anisotropic(m, s, rng, rest):
    theta = rng.uniform(0, np.pi)  # the stiff axis
    u, _, u_max, c = _displacements(m, s, rest, "anisotropic_gel", ANISO_PX, MAX_ANISO)
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    scale = rot @ np.diag([1.0 - c, 1.0 + c]) @ rot.T
    return rest + u @ scale.T


# one library for both self-tests (loop.selftest cases `unlisted:<name>`, loop.selftest.generative draws)
UNLISTED: dict[str, Unlisted] = {u.name: u for u in (
    Unlisted("image_distortion", "optical", _distortion, (1.0, 2.5)),
    Unlisted("tangential_distortion", "optical", _tangential, (1.0, 2.5)),
    Unlisted("marker_defect", "sensor", _defect, (1.0, 2.5)),
    Unlisted("strain_stiffening", "physical", _stiffening, (1.0, 2.5)),
    Unlisted("anisotropic_gel", "physical", _anisotropic, (1.0, 2.5)),
)}


def twin_rest(binding_rest_px: np.ndarray, template_px: np.ndarray, params) -> np.ndarray:
    """The rest markers of the twin with `params`: the nominal binding's rest, moved towards the template by the
    anchor (loop.simulate; the camera re-binds but keeps the rest image, the mount moves the whole sensor)."""
    rest = np.asarray(binding_rest_px, np.float64)
    return rest + float(params.get("marker_anchor", 0.0)) * (np.asarray(template_px, np.float64) - rest)
