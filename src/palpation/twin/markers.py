"""Markers bound to the dome surface, the projected vessel centreline and the label rule (SPEC §5, §7).

A marker is not a mesh node: each rest marker of the real template is tied to the 5 dome-surface
nodes whose rest projections lie nearest in the image, with inverse-distance weights, and each frame
it is the weighted mean of those nodes' projections (pixels are averaged, not 3-D points).

The per-frame projection runs as Warp kernels over (env, marker) and (env, centreline point), reading
device-resident node positions and a device copy of the whole pose schedule, so a GPU run never
round-trips through the host inside the frame loop. The numpy functions are the reference the tests
compare the kernels against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp
from scipy.spatial import cKDTree

from palpation.camera import DEFAULT_CAMERA, LENS_TO_TIP_MM, Fisheye

LENS_TO_TIP_M = LENS_TO_TIP_MM * 1e-3  # camera E = body B + (0, 0, 19 mm)
N_NEAREST = 5
LABEL_RADIUS_PX = 30.0
VESSEL_ORIGIN_M = np.array([0.095, 0.195, 0.060]) * 0.2  # SPEC §3.1, sim -> m
VESSEL_LENGTH_M = 0.040
N_CENTRELINE = 50


@dataclass(frozen=True)
class MarkerBinding:
    """node_ix (127, k) mesh node indices, weights (127, k) summing to 1, rest_px (127, 2) bound rest."""

    node_ix: np.ndarray
    weights: np.ndarray
    rest_px: np.ndarray
    template_px: np.ndarray

    @property
    def residual_px(self) -> np.ndarray:
        """(127,) distance between each bound rest marker and its template marker."""
        return np.linalg.norm(self.rest_px - self.template_px, axis=1)


def body_to_camera(points_B: np.ndarray) -> np.ndarray:
    return np.asarray(points_B, dtype=np.float64) + np.array([0.0, 0.0, LENS_TO_TIP_M])


def world_to_camera(points_A: np.ndarray, T_BA: np.ndarray) -> np.ndarray:
    """(..., P, 3) world points and (..., 4, 4) poses -> camera-frame points (..., P, 3)."""
    R, t = T_BA[..., :3, :3], T_BA[..., None, :3, 3]
    points_B = np.einsum("...ji,...pj->...pi", R, np.asarray(points_A, dtype=np.float64) - t)
    return body_to_camera(points_B)


def bind_markers(nodes_B: np.ndarray, dome_nodes: np.ndarray, template_px: np.ndarray,
                 camera: Fisheye = DEFAULT_CAMERA, k: int = N_NEAREST) -> MarkerBinding:
    """Tie each template marker to its k nearest projected rest dome-surface nodes (SPEC §5.2)."""
    dome_nodes = np.asarray(dome_nodes)
    if len(dome_nodes) < k:
        raise ValueError(f"marker binding needs at least {k} dome-surface nodes, "
                         f"the mesh has {len(dome_nodes)}")
    rest_node_px = camera.project(body_to_camera(np.asarray(nodes_B)[dome_nodes]))
    return _bind_query(rest_node_px, cKDTree(rest_node_px), dome_nodes, template_px, k)


def _bind_query(rest_node_px: np.ndarray, tree, dome_nodes: np.ndarray, template_px: np.ndarray,
                k: int = N_NEAREST) -> MarkerBinding:
    """bind_markers' query on projected rest nodes and their KD-tree (shared by several bindings)."""
    dist, local = tree.query(np.asarray(template_px, dtype=np.float64), k=k)
    inv = 1.0 / np.maximum(dist, 1e-9)  # a marker exactly on a node takes (almost) all its weight
    weights = inv / inv.sum(axis=1, keepdims=True)
    rest_px = np.einsum("mk,mkc->mc", weights, rest_node_px[local])
    return MarkerBinding(node_ix=dome_nodes[local].astype(np.int32), weights=weights,
                         rest_px=rest_px, template_px=np.asarray(template_px, dtype=np.float64))


def project_markers_np(binding: MarkerBinding, nodes_A: np.ndarray, T_BA: np.ndarray,
                       camera: Fisheye = DEFAULT_CAMERA) -> np.ndarray:
    """Numpy reference: (n, N, 3) world nodes and (n, 4, 4) poses -> (n, 127, 2) marker pixels."""
    nodes_A = np.asarray(nodes_A)
    n, m, k = len(nodes_A), *binding.node_ix.shape
    picked = nodes_A[:, binding.node_ix.reshape(-1)]  # (n, m*k, 3)
    px = camera.project(world_to_camera(picked, T_BA)).reshape(n, m, k, 2)
    return np.einsum("mk,nmkc->nmc", binding.weights, px)


@dataclass(frozen=True)
class ImageSimilarity:
    """A camera error as a similarity of the nominal image about the principal point (twin.config.CameraConfig).

    u -> c + f_scale R(rotation) (u - c) + (dx, dy). The equidistant projection is linear in f and c,
    so this is exactly a camera with focal length f * f_scale, principal point c + (dx, dy) and a
    rotated image.
    """

    f_scale: float = 1.0
    rotation_deg: float = 0.0
    dx_px: float = 0.0
    dy_px: float = 0.0
    cx_px: float = DEFAULT_CAMERA.cx_px
    cy_px: float = DEFAULT_CAMERA.cy_px

    @classmethod
    def from_config(cls, cam, camera: Fisheye = DEFAULT_CAMERA) -> "ImageSimilarity":
        return cls(cam.f_scale, cam.rotation_deg, cam.dx_px, cam.dy_px, camera.cx_px, camera.cy_px)

    @property
    def is_identity(self) -> bool:
        return (self.f_scale, self.rotation_deg, self.dx_px, self.dy_px) == (1.0, 0.0, 0.0, 0.0)

    def linear(self) -> np.ndarray:
        a = np.radians(self.rotation_deg)
        return self.f_scale * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])

    def apply(self, px: np.ndarray) -> np.ndarray:
        c = np.array([self.cx_px, self.cy_px])
        return (np.asarray(px, np.float64) - c) @ self.linear().T + c + np.array([self.dx_px, self.dy_px])

    def inverse(self, px: np.ndarray) -> np.ndarray:
        c = np.array([self.cx_px, self.cy_px])
        q = np.asarray(px, np.float64) - c - np.array([self.dx_px, self.dy_px])
        return q @ np.linalg.inv(self.linear()).T + c


@dataclass(frozen=True)
class CameraBinding:
    """Markers seen through a camera error, anchored at the nominal twin's rest markers.

    The real rest photo fixes where the markers are in the image (the template), so a camera error
    changes which dome points they sit on and how their motion maps to pixels, not the rest image:
    the true camera's nearest nodes to the template are the nominal image's nearest nodes to
    S^-1(template), with the same inverse-distance weights (a similarity scales all distances
    alike). Markers = anchor + A (m - m_rest), where m is the nominal projection with `binding`,
    m_rest its rest value and A the similarity's linear part. Anchoring at the nominal binding's rest
    keeps the binding's own interpolation offset (IDW is not exact) out of the camera effect.
    """

    binding: MarkerBinding  # nodes and weights for S^-1(template); rest_px = m_rest
    anchor_px: np.ndarray  # (127, 2) rest markers of the nominal binding
    image: ImageSimilarity

    def markers(self, nominal_px: np.ndarray) -> np.ndarray:
        """(..., 127, 2) nominal projections with `binding` -> markers in the true image."""
        moved = np.asarray(nominal_px, np.float64) - self.binding.rest_px
        return self.anchor_px + moved @ self.image.linear().T


def bind_markers_through(nodes_B: np.ndarray, dome_nodes: np.ndarray, template_px: np.ndarray,
                         image: ImageSimilarity, camera: Fisheye = DEFAULT_CAMERA) -> CameraBinding:
    template_px = np.asarray(template_px, np.float64)
    dome_nodes = np.asarray(dome_nodes)
    if len(dome_nodes) < N_NEAREST:
        return bind_markers(nodes_B, dome_nodes, template_px, camera)  # raises its clear error
    # one projection and KD-tree of the rest nodes for both bindings (the loop's camera grid makes many)
    rest_node_px = camera.project(body_to_camera(np.asarray(nodes_B)[dome_nodes]))
    tree = cKDTree(rest_node_px)
    nominal = _bind_query(rest_node_px, tree, dome_nodes, template_px)
    moved = _bind_query(rest_node_px, tree, dome_nodes, image.inverse(template_px))
    return CameraBinding(moved, nominal.rest_px, image)


def centreline_A(n_points: int = N_CENTRELINE) -> np.ndarray:
    """(50, 3) world points evenly spaced along the vessel axis, metres."""
    s = np.linspace(0.0, 1.0, n_points)[:, None]
    return VESSEL_ORIGIN_M + s * np.array([VESSEL_LENGTH_M, 0.0, 0.0])


def project_points_np(points_A: np.ndarray, T_BA: np.ndarray, camera: Fisheye = DEFAULT_CAMERA) -> np.ndarray:
    """(P, 3) world points through n camera poses (n, 4, 4) -> (n, P, 2) pixels."""
    points = np.broadcast_to(points_A, (len(T_BA), *np.shape(points_A)))
    return camera.project(world_to_camera(points, T_BA))


def marker_labels(markers_px: np.ndarray, centreline_px: np.ndarray, contact: np.ndarray,
                  radius_px: float = LABEL_RADIUS_PX) -> np.ndarray:
    """SPEC §7: positive iff the frame has contact and the marker is < 30 px from the centreline.

    markers (F, 127, 2), centreline (F, P, 2), contact (F,) -> (F, 127) int8.
    """
    m, c = np.asarray(markers_px), np.asarray(centreline_px)
    # the nearest point's squared distance, then one sqrt: bit for bit norm(m - c, axis=-1).min()
    # (same float ops, sqrt is monotonic) without its (F, 127, P, 2) temporaries, ~10x faster
    best = None
    for p in range(c.shape[1]):
        dx, dy = m[..., 0] - c[:, p, None, 0], m[..., 1] - c[:, p, None, 1]
        s = dx * dx + dy * dy
        best = s if best is None else np.minimum(best, s, out=best)
    return ((np.sqrt(best) < radius_px) & np.asarray(contact, bool)[:, None]).astype(np.int8)


# --- Warp kernels ---------------------------------------------------------------------------------

@wp.struct
class FisheyeParams:
    f_px: float
    cx_px: float
    cy_px: float
    lens_to_tip_m: float


def fisheye_params(camera: Fisheye = DEFAULT_CAMERA) -> FisheyeParams:
    p = FisheyeParams()
    p.f_px, p.cx_px, p.cy_px, p.lens_to_tip_m = camera.f_px, camera.cx_px, camera.cy_px, LENS_TO_TIP_M
    return p


@wp.func
def project_world(x: wp.vec3, T_AB: wp.mat44, cam: FisheyeParams) -> wp.vec2:
    """World point -> body (inverse pose) -> camera E -> equidistant fisheye pixel."""
    p = wp.transform_point(T_AB, x) + wp.vec3(0.0, 0.0, cam.lens_to_tip_m)
    # atan2, not acos(z/|p|): in float32 acos loses ~3e-4 rad (~0.1 px) near the optical axis
    theta = wp.atan2(wp.sqrt(p[0] * p[0] + p[1] * p[1]), p[2])
    phi = wp.atan2(p[1], p[0])
    r = cam.f_px * theta
    return wp.vec2(cam.cx_px + r * wp.cos(phi), cam.cy_px + r * wp.sin(phi))


@wp.kernel
def project_markers(
    x: wp.array[wp.vec3],
    n_nodes: int,
    poses_AB: wp.array2d[wp.mat44],
    frame_index: wp.array[wp.int32],
    frame_offset: int,
    node_ix: wp.array2d[wp.int32],
    weights: wp.array2d[float],
    cam: FisheyeParams,
    first: wp.array[wp.int32],
    end: wp.array[wp.int32],
    markers: wp.array3d[wp.vec2],
):
    env, m = wp.tid()
    frame = frame_index[0] + frame_offset  # a device counter: one graph serves every frame
    if frame < first[env] or frame >= end[env]:  # outside this env's recorded window
        return
    T_AB = poses_AB[frame, env]
    acc = wp.vec2(0.0, 0.0)
    for j in range(node_ix.shape[1]):
        acc += weights[m, j] * project_world(x[env * n_nodes + node_ix[m, j]], T_AB, cam)
    markers[frame - first[env], env, m] = acc


@wp.kernel
def project_centreline(
    points: wp.array[wp.vec3],
    poses_AB: wp.array2d[wp.mat44],
    frame_index: wp.array[wp.int32],
    frame_offset: int,
    cam: FisheyeParams,
    first: wp.array[wp.int32],
    end: wp.array[wp.int32],
    out: wp.array3d[wp.vec2],
):
    env, p = wp.tid()
    frame = frame_index[0] + frame_offset
    if frame < first[env] or frame >= end[env]:
        return
    out[frame - first[env], env, p] = project_world(points[p], poses_AB[frame, env], cam)


class MarkerProjector:
    """Device-side marker and centreline extraction for a batch of envs following a pose schedule.

    `poses_BA` (F, n, 4, 4) is uploaded once as inverse poses. Env i records frames
    [first[i], end[i]); `extract(x, frame)` writes row frame - first[i] of the output buffers, so
    envs of different lengths share one launch and a finished env (holding its pose) writes nothing.
    """

    def __init__(self, binding: MarkerBinding, poses_BA: np.ndarray, n_nodes: int, first: np.ndarray,
                 end: np.ndarray, camera: Fisheye = DEFAULT_CAMERA, device=None):
        self.device = wp.get_device(device)
        self.n_envs = poses_BA.shape[1]
        self.n_nodes, self.n_markers = n_nodes, len(binding.node_ix)
        first, end = np.asarray(first, np.int32), np.asarray(end, np.int32)
        if np.any(end <= first) or np.any(end > len(poses_BA)):
            raise ValueError(f"recording windows must satisfy 0 <= first < end <= {len(poses_BA)} frames")
        n_slots = int((end - first).max())
        inv = np.linalg.inv(poses_BA).astype(np.float32)  # invert in float64, then store float32
        self.poses_AB = wp.array(inv, dtype=wp.mat44, device=self.device)
        self.first = wp.array(first, dtype=wp.int32, device=self.device)
        self.end = wp.array(end, dtype=wp.int32, device=self.device)
        self.node_ix = wp.array(binding.node_ix, dtype=wp.int32, device=self.device)
        self.weights = wp.array(binding.weights.astype(np.float32), dtype=float, device=self.device)
        self.points = wp.array(centreline_A().astype(np.float32), dtype=wp.vec3, device=self.device)
        self.cam = fisheye_params(camera)
        self.markers = wp.zeros((n_slots, self.n_envs, self.n_markers), dtype=wp.vec2, device=self.device)
        self.centreline = wp.zeros((n_slots, self.n_envs, N_CENTRELINE), dtype=wp.vec2, device=self.device)
        self._zero = wp.zeros(1, dtype=wp.int32, device=self.device)

    def extract(self, x: wp.array, frame: int) -> None:
        """`x`: device positions of all envs, env-major (n * N) vec3, world frame."""
        self.extract_at(x, self._zero, int(frame))

    def extract_at(self, x: wp.array, frame_index: wp.array, offset: int = 0) -> None:
        """`extract` at frame frame_index[0] + offset, read on the device (capturable once, replayed
        every frame while the simulator advances frame_index)."""
        wp.launch(project_markers, dim=(self.n_envs, self.n_markers),
                  inputs=[x, self.n_nodes, self.poses_AB, frame_index, offset, self.node_ix, self.weights,
                          self.cam, self.first, self.end],
                  outputs=[self.markers], device=self.device)
        wp.launch(project_centreline, dim=(self.n_envs, N_CENTRELINE),
                  inputs=[self.points, self.poses_AB, frame_index, offset, self.cam, self.first, self.end],
                  outputs=[self.centreline], device=self.device)

    def results(self) -> tuple[np.ndarray, np.ndarray]:
        """(slots, n, 127, 2) markers and (slots, n, 50, 2) centreline pixels, float32."""
        return self.markers.numpy(), self.centreline.numpy()
