"""The sensor solid of SPEC §2.1 as linear tetrahedra (gmsh OCC), with the node sets of §2.2.

Coordinates are metres in the body frame B: origin at the dome tip, +z out of the dome (the gmsh
model is built in mm and shifted so that max z = 0). Node sets are classified in the original mm
coordinates, before the shift, exactly as SPEC §2.2 words them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from palpation.io import save_npz
from palpation.readers import read_npz

# gmsh Mesh.CharacteristicLengthFactor per named resolution; 0.3 reproduces the reference mesh.
RESOLUTIONS = {"reference": 0.3, "coarse": 0.7}
_MESH_KEYS = ("nodes", "tets", "surface_nodes", "contact_tris", "dome_nodes", "fixed", "resolution")

# SPEC §2.1 geometry, mm
DOME_ROC_MM = 38.6
WALL_R_MM, FLANGE_R_MM = 19.0, 20.0
BASE_Z_MM, HEIGHT_MM, FLANGE_H_MM = 20.6, 18.0, 7.0
CAP_Z_MM, FLANGE_TOP_MM, FIXED_Z_MM = 33.6, 27.6, 23.6
_TOL_MM = 1e-6  # node coordinates on a set boundary (z = 27.6, z = 33.6) are exact to ~1e-13


@dataclass
class SensorMesh:
    nodes: np.ndarray  # (N, 3) float64, metres, body frame B
    tets: np.ndarray  # (T, 4) int32, positive orientation: det[x1-x0, x2-x0, x3-x0] > 0
    surface_nodes: np.ndarray  # (S,) int32, outer skin that can touch (SPEC §2.2)
    contact_tris: np.ndarray  # (K, 3) int32, boundary triangles with 3 surface nodes
    dome_nodes: np.ndarray  # (D,) int32, surface nodes on the spherical cap (marker binding)
    fixed: np.ndarray  # (N,) bool, nodes driven by the rigid base motion
    resolution: str = "custom"

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_tets(self) -> int:
        return len(self.tets)

    def save(self, path: str | os.PathLike) -> None:
        save_npz(path, nodes=self.nodes, tets=self.tets, surface_nodes=self.surface_nodes,
                 contact_tris=self.contact_tris, dome_nodes=self.dome_nodes, fixed=self.fixed,
                 resolution=np.array(self.resolution))

    @classmethod
    def load(cls, path: str | os.PathLike) -> "SensorMesh":
        """The mesh file written by `save` (rule `mesh`), every array checked: a damaged or foreign file would
        otherwise fail inside the FEM setup (an index error) or simulate a wrong solid."""
        path = Path(path)
        fix = "rebuild it with `snakemake results/twin/mesh_<resolution>.npz` (or point `mesh` at such a file)"
        z = read_npz(path, _MESH_KEYS, fix, what="mesh file", finite=("nodes",),
                     shapes={"nodes": (None, 3), "tets": (None, 4), "surface_nodes": (None,),
                             "contact_tris": (None, 3), "dome_nodes": (None,), "fixed": (None,), "resolution": ()},
                     dtypes={"tets": "iu", "surface_nodes": "iu", "contact_tris": "iu", "dome_nodes": "iu",
                             "fixed": "b", "resolution": "U"})
        n = len(z["nodes"])
        for key in ("tets", "surface_nodes", "contact_tris", "dome_nodes"):
            if z[key].size and (z[key].min() < 0 or z[key].max() >= n):
                raise ValueError(f"mesh file {path}: `{key}` indexes nodes outside 0..{n - 1}; {fix}")
        if not len(z["tets"]) or len(z["fixed"]) != n:
            raise ValueError(f"mesh file {path}: {len(z['tets'])} tets and {len(z['fixed'])} `fixed` flags for "
                             f"{n} nodes; {fix}")
        return cls(nodes=z["nodes"], tets=z["tets"], surface_nodes=z["surface_nodes"],
                   contact_tris=z["contact_tris"], dome_nodes=z["dome_nodes"], fixed=z["fixed"],
                   resolution=str(z["resolution"]))

    def stats(self) -> dict:
        """Counts, tet-edge lengths (mm) and volume (mm^3) as tabulated in SPEC §2.2.

        The mean edge is taken over the 6 edges of every tet (shared edges counted once per tet):
        that is the reference's recorded 2.3230613737553244 mm; the mean over unique edges is 2.285.
        """
        e = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
        pairs = self.tets[:, e].reshape(-1, 2)  # 6 edges per tet, shared edges counted per tet
        lengths = np.linalg.norm(self.nodes[pairs[:, 0]] - self.nodes[pairs[:, 1]], axis=1) * 1e3
        unique = np.unique(np.sort(pairs, axis=1), axis=0)
        unique_mean = np.linalg.norm(self.nodes[unique[:, 0]] - self.nodes[unique[:, 1]], axis=1).mean()
        return {"resolution": self.resolution, "nodes": self.n_nodes, "tets": self.n_tets,
                "boundary_tris": len(boundary_triangles(self.tets)),
                "surface_nodes": len(self.surface_nodes), "contact_tris": len(self.contact_tris),
                "dome_nodes": len(self.dome_nodes), "fixed_nodes": int(self.fixed.sum()),
                "edge_min_mm": float(lengths.min()), "edge_mean_mm": float(lengths.mean()),
                "edge_max_mm": float(lengths.max()), "edge_mean_unique_mm": float(unique_mean * 1e3),
                "volume_mm3": float(tet_volumes(self.nodes, self.tets).sum() * 1e9)}


def tet_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes det[x1-x0, x2-x0, x3-x0] / 6."""
    x = nodes[tets]
    return np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) / 6


def orient_positive(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    tets = np.array(tets, dtype=np.int32)
    neg = tet_volumes(nodes, tets) < 0
    tets[neg, 1], tets[neg, 2] = tets[neg, 2], tets[neg, 1].copy()
    return tets


def boundary_triangles(tets: np.ndarray) -> np.ndarray:
    """Faces that belong to exactly one tet, (B, 3) int32."""
    faces = tets[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    _, idx, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    return faces[np.sort(idx[counts == 1])].astype(np.int32)


def _import_gmsh():
    """gmsh, imported only when a mesh is built: a GPU node runs on cached meshes without it."""
    try:
        import gmsh
    except ImportError as exc:
        raise ModuleNotFoundError(
            "gmsh is not installed, so no mesh can be built here: build results/twin/mesh_<resolution>.npz "
            "where gmsh is (`snakemake results/twin/mesh_coarse.npz`) and point PALPATION_MESH_CACHE at "
            "that folder, or `pip install gmsh`") from exc
    return gmsh


def _generate_gmsh_mm(length_factor: float) -> tuple[np.ndarray, np.ndarray]:
    gmsh = _import_gmsh()

    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)  # HXT is only deterministic single-threaded
        gmsh.model.add("vitactip")
        occ = gmsh.model.occ
        sphere = occ.addSphere(0, 0, 0, DOME_ROC_MM)
        wall = occ.addCylinder(0, 0, BASE_Z_MM, 0, 0, HEIGHT_MM, WALL_R_MM)
        cap, _ = occ.intersect([(3, sphere)], [(3, wall)])
        flange = occ.addCylinder(0, 0, BASE_Z_MM, 0, 0, FLANGE_H_MM, FLANGE_R_MM)
        occ.fuse(cap, [(3, flange)])
        occ.synchronize()
        for name, value in [("Algorithm3D", 10), ("Algorithm", 6), ("Optimize", 1),
                            ("OptimizeNetgen", 1), ("CharacteristicLengthFactor", length_factor)]:
            gmsh.option.setNumber(f"Mesh.{name}", value)
        gmsh.model.mesh.generate(3)
        tags, xyz, _ = gmsh.model.mesh.getNodes()
        types, _, conn = gmsh.model.mesh.getElements(3)
        tet_conn = conn[list(types).index(4)].reshape(-1, 4)  # gmsh type 4 = 4-node tet
    finally:
        gmsh.finalize()
    used, tets = np.unique(tet_conn, return_inverse=True)  # drop nodes no tet uses
    lookup = {int(t): i for i, t in enumerate(tags)}
    nodes = xyz.reshape(-1, 3)[[lookup[int(u)] for u in used]]
    return nodes, tets.reshape(-1, 4)


def classify_nodes_mm(nodes_mm: np.ndarray, tets: np.ndarray) -> dict[str, np.ndarray]:
    """SPEC §2.2 node sets from mm coordinates in the original (unshifted) frame."""
    x, y, z = nodes_mm.T
    rho, r = np.hypot(x, y), np.linalg.norm(nodes_mm, axis=1)
    t = _TOL_MM
    surface = ((z > CAP_Z_MM + t) & (r > 38.5)) | ((z > FLANGE_TOP_MM + t) & (z <= CAP_Z_MM + t)
                                                  & (rho > 18.9))
    fixed = (z < FIXED_Z_MM - t) | ((rho > WALL_R_MM + t) & (z < FLANGE_TOP_MM - t))
    tris = boundary_triangles(tets)
    contact = tris[surface[tris].all(axis=1)]
    dome = np.flatnonzero(surface & (z >= CAP_Z_MM - t))
    return {"surface_nodes": np.flatnonzero(surface).astype(np.int32), "contact_tris": contact,
            "dome_nodes": dome.astype(np.int32), "fixed": fixed}


def skin_depth_m(points_B: np.ndarray) -> np.ndarray:
    """Depth (m) of body-frame points below the outer skin: the dome cap and the wall above the flange.

    Analytic (SPEC §2.1), so it does not depend on the mesh resolution; inf at or below the flange top.
    """
    p = np.asarray(points_B, np.float64) * 1e3
    p = p + np.array([0.0, 0.0, DOME_ROC_MM])  # back to the gmsh frame (sphere at the origin)
    depth = np.minimum(DOME_ROC_MM - np.linalg.norm(p, axis=-1), WALL_R_MM - np.hypot(p[..., 0], p[..., 1]))
    return np.where(p[..., 2] > FLANGE_TOP_MM, np.maximum(depth, 0.0) * 1e-3, np.inf)


def shell_weights(nodes: np.ndarray, tets: np.ndarray, thickness_m: float) -> np.ndarray:
    """(T,) fraction of each tet's volume within `thickness_m` of the outer skin (layered skin).

    Estimated on the 35 points of a degree-4 barycentric lattice, so a shell thinner than the tets of
    a coarse mesh still stiffens the outer tets in proportion instead of all or nothing.
    """
    if thickness_m <= 0:
        return np.zeros(len(tets))
    lattice = np.array([(i, j, k, 4 - i - j - k) for i in range(5) for j in range(5 - i)
                        for k in range(5 - i - j)], np.float64) / 4.0
    pts = np.einsum("sk,tkc->tsc", lattice, np.asarray(nodes, np.float64)[tets])
    return (skin_depth_m(pts) < thickness_m).mean(axis=1)


_PER_MESH: dict[tuple, tuple] = {}  # (id(mesh), key) -> (mesh, value); the mesh held so its id stays its own


def per_mesh(mesh: SensorMesh, key: tuple, build):
    """`build()` once per mesh object and key: derived constants that every twin on the same mesh shares (the
    residual loop builds a twin per call: shell fractions, the resident kernel's colouring). At most 16 kept."""
    hit = _PER_MESH.get((id(mesh), key))
    if hit is None or hit[0] is not mesh:
        if len(_PER_MESH) >= 16:
            _PER_MESH.pop(next(iter(_PER_MESH)))
        hit = _PER_MESH[(id(mesh), key)] = (mesh, build())
    return hit[1]


def build_sensor_mesh(resolution: str = "coarse", length_factor: float | None = None) -> SensorMesh:
    """Mesh the sensor; `length_factor` overrides the factor of a named resolution."""
    if length_factor is None:
        if resolution not in RESOLUTIONS:
            raise ValueError(f"unknown mesh resolution {resolution!r}: use one of "
                             f"{sorted(RESOLUTIONS)} or pass length_factor")
        length_factor = RESOLUTIONS[resolution]
    nodes_mm, tets = _generate_gmsh_mm(length_factor)
    tets = orient_positive(nodes_mm, tets)
    sets = classify_nodes_mm(nodes_mm, tets)
    nodes = nodes_mm * 1e-3
    nodes[:, 2] -= nodes[:, 2].max()  # origin at the dome tip
    return SensorMesh(nodes=nodes, tets=tets, resolution=resolution, **sets)


def cached_sensor_mesh(resolution: str, cache_dir: str | os.PathLike | None = None) -> SensorMesh:
    """The mesh cached by rule `mesh` (`<cache_dir>/mesh_<resolution>.npz`) if there, else a new one.

    Machines without gmsh (e.g. a GPU node) run on meshes built elsewhere this way.
    """
    if cache_dir is not None:
        path = Path(cache_dir) / f"mesh_{resolution}.npz"
        if path.exists():
            return SensorMesh.load(path)
    return build_sensor_mesh(resolution)


def box_mesh(size=(0.01, 0.01, 0.01), divisions=(2, 2, 2), fixed: str = "bottom") -> SensorMesh:
    """A structured box of tets (6 per cell, Kuhn split) in z in [-lz, 0], for tests.

    `fixed`: "bottom" (z = -lz face driven), "none". Surface/dome = the top face z = 0.
    """
    (lx, ly, lz), (nx, ny, nz) = size, divisions
    g = np.stack(np.meshgrid(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1),
                             np.linspace(-lz, 0, nz + 1), indexing="ij"), -1).reshape(-1, 3)
    idx = np.arange(len(g)).reshape(nx + 1, ny + 1, nz + 1)
    kuhn = [(0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)]
    tets = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                c = [idx[i + a, j + b, k + d] for a in (0, 1) for b in (0, 1) for d in (0, 1)]
                tets += [[c[p] for p in (q[0], q[1], q[2], q[3])] for q in kuhn]
    # corner order c = (i,j,k) bits (a,b,d) -> index 4a+2b+d; Kuhn paths through that cube
    tets = orient_positive(g, np.array(tets))
    top = np.isclose(g[:, 2], 0.0)
    tris = boundary_triangles(tets)
    fixed_mask = np.isclose(g[:, 2], -lz) if fixed == "bottom" else np.zeros(len(g), bool)
    top_nodes = np.flatnonzero(top).astype(np.int32)
    return SensorMesh(nodes=g, tets=tets, surface_nodes=top_nodes, contact_tris=tris[top[tris].all(axis=1)],
                      dome_nodes=top_nodes, fixed=fixed_mask, resolution="box")


def build_vessel_points(center=(0.039, 0.039, 0.012), radius: float = 0.002, length: float = 0.040,
                        length_factor: float = 0.3) -> np.ndarray:
    """Nodes (P, 3) of the reference's vessel tet mesh, world metres, axis along +x (SPEC §3.1).

    gmsh cylinder along z in mm, rotated R_y(90 deg) onto x; with the reference options this is
    the reference's 506-node mesh. Only the nearest-centroid contact rule uses these points.
    """
    gmsh = _import_gmsh()

    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("vessel")
        gmsh.model.occ.addCylinder(0, 0, 0, 0, 0, length * 1e3, radius * 1e3)
        gmsh.model.occ.synchronize()
        for name, value in [("Algorithm3D", 10), ("Algorithm", 6), ("Optimize", 1),
                            ("OptimizeNetgen", 1), ("CharacteristicLengthFactor", length_factor)]:
            gmsh.option.setNumber(f"Mesh.{name}", value)
        gmsh.model.mesh.generate(3)
        _, xyz, _ = gmsh.model.mesh.getNodes()
    finally:
        gmsh.finalize()
    p = xyz.reshape(-1, 3) * 1e-3
    along_x = np.stack([p[:, 2], p[:, 1], -p[:, 0]], axis=1)  # R_y(90): (x, y, z) -> (z, y, -x)
    return along_x + np.asarray(center) - [0.5 * length, 0.0, 0.0]


def projected_node_area(mesh: SensorMesh) -> np.ndarray:
    """(N,) rest area of each node's share (1/3) of its contact triangles, projected on the body xy plane:
    what a Winkler foundation under the dome presses on (twin.contact); 0 off the contact skin."""
    tri = np.asarray(mesh.contact_tris, np.int64)
    area = np.zeros(mesh.n_nodes)
    if len(tri):
        p = mesh.nodes[tri]
        cross_z = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 2]
        np.add.at(area, tri.ravel(), np.repeat(0.5 * np.abs(cross_z) / 3.0, 3))
    return area.astype(np.float32)


def morton_order(points: np.ndarray, bits: int = 10) -> np.ndarray:
    """Indices that sort 3-D points along a Morton (Z-order) curve of their bounding box."""
    span = max(float((points.max(axis=0) - points.min(axis=0)).max()), 1e-30)
    q = ((points - points.min(axis=0)) / span * (2**bits - 1)).astype(np.int64)
    code = np.zeros(len(points), np.int64)
    for b in range(bits):
        for d in range(3):
            code |= ((q[:, d] >> b) & 1) << (3 * b + d)
    return np.argsort(code, kind="stable")
