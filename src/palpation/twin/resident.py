"""Frame-resident FEM kernel (issue 17, `twin.integrator.kernel=resident`): one block per env.

A block loads its env's x, v into shared-memory tiles, keeps f there too, runs all substeps of
the frame, and writes x, v (and the last substep's f_c) back once. The elastic pass runs the
moving tets colour by colour (no two tets of a colour share a node that needs its force), so the
per-thread corner forces go into the shared f without atomics, in a fixed order: deterministic,
and the same sums on the CPU (one lane, or cooperative fibers with `wp.config.enable_cpu_blocks`)
as on a GPU. The sums run in colour order instead of the mesh order of the streamed gather, so
the two paths differ by float32 rounding only. The per-tet and per-node arithmetic is the streamed
kernels' own (`tet_forces`, `surface_contact_force`). Every `wp.tile_scatter_*` call ends with a
block barrier: that is the only sync Warp 1.19 offers inside a loop, and it is what orders the
passes (elastic -> node -> next substep). docs/twin.md gives the design and its roofline.
"""

from __future__ import annotations

import functools
import threading
from contextlib import contextmanager
from typing import Iterator

import numpy as np
import warp as wp

from palpation.twin.config import LAYERED_VARIANTS
from palpation.twin.config import RESIDENT_COLORINGS as COLORINGS
from palpation.twin.config import RESIDENT_VARIANTS as VARIANTS
from palpation.twin.contact import ContactParams
from palpation.twin.elasticity import rest_shape, tet_forces
from palpation.twin.mesh import per_mesh
from palpation.twin.resident_sync import (NEED_BIT, chunk_table, contact_and_control, onesync_kernel, pack_corners,
                                         packed_kernel)

VEC3 = 12
# twin.integrator.kernel=auto on the CPU: the "compact" variant in mesh order with one lane a block sums every force
# in the streamed scatter's order, so it gives the streamed kernels' bits, 1.5x faster on the coarse mesh (one
# launch a frame instead of two a substep; tests/twin/test_resident.py, docs/twin.md)
CPU_AUTO = "compact"
CPU_SHARED_BYTES = 256 * 1024  # Warp's fixed shared-memory block of a CPU launch (WP_MAX_CPU_SHARED in tile.h)
# Warp's CPU tile kernels find that block through one static pointer (tile.h: its JIT has no thread-local storage on
# x86-64), so two threads of a process running them at once corrupt each other's tiles (the residual loop's worker
# threads crashed): a CPU twin on the resident kernel advances its frames under this lock
CPU_TILES_LOCK = threading.Lock()


def color_tets(tets: np.ndarray, needs_force: np.ndarray, cap: int | None = None,
               coloring: str = "mesh_order") -> tuple[np.ndarray, np.ndarray]:
    """Greedy colouring: no two tets of a colour share a node that needs its force.

    A colour holds at most `cap` tets (one block's lanes): the first colours fill whole chunks
    instead of the plain greedy's 560, 547, ... 16, so fewer chunks (barriers) run per substep.
    coloring="mesh_order" colours the tets in mesh order; "largest_first" first those whose busiest
    force node has the most tets (reference mesh, cap 512: 41 colours instead of 44; 40 is the floor).
    Returns (order, start): tets[order] lists colour 0 first, each colour in visiting order, and colour
    k is order[start[k]:start[k+1]]. Driven interior nodes are ignored: their force is discarded.
    """
    tets = np.asarray(tets)
    cap = cap or len(tets)
    if coloring not in COLORINGS:
        raise ValueError(f"twin.integrator.resident_coloring={coloring!r}: use one of {COLORINGS}")
    visit = np.arange(len(tets))
    if coloring == "largest_first":
        degree = np.bincount(tets[needs_force[tets]], minlength=len(needs_force))
        visit = np.argsort(-np.where(needs_force[tets], degree[tets], 0).max(axis=1), kind="stable")
    used: list[set[int]] = [set() for _ in range(len(needs_force))]  # colours seen at each node
    color = np.empty(len(tets), np.int64)
    size: list[int] = []
    for t in visit:
        nodes = [int(i) for i in tets[t] if needs_force[i]]
        taken = set().union(*(used[i] for i in nodes)) if nodes else set()
        c = 0
        while c in taken or (c < len(size) and size[c] >= cap):
            c += 1
        if c == len(size):
            size.append(0)
        size[c] += 1
        color[t] = c
        for i in nodes:
            used[i].add(c)
    order = visit[np.argsort(color[visit], kind="stable")]
    start = np.concatenate([[0], np.cumsum(np.bincount(color))]).astype(np.int32)
    return order, start


def shared_bytes(n_nodes: int) -> int:
    """Shared memory of one block: x, v and f of its env (vec3 float32 tiles)."""
    return 3 * n_nodes * VEC3


@functools.lru_cache(maxsize=None)
def resident_kernel(n_nodes: int):
    """The frame kernel for meshes of `n_nodes` nodes (tile shapes are compile-time constants)."""

    @wp.kernel(enable_backward=False, module="unique")
    def frame_resident(
        tets: wp.array2d[wp.int32],
        dm_inv: wp.array[wp.mat33],
        color_start: wp.array[wp.int32],
        n_colors: int,
        need: wp.array[wp.int32],
        inv_mass: wp.array[float],
        fixed: wp.array[wp.int32],
        on_surface: wp.array[wp.int32],
        env_mu: wp.array[float],
        env_lam: wp.array[float],
        alpha: float,
        beta: float,
        dt: float,
        substeps: int,
        p: ContactParams,
        v_ctl: wp.array[wp.vec3],
        x: wp.array[wp.vec3],
        v: wp.array[wp.vec3],
        f_c: wp.array[wp.vec3],
        contact_flag: wp.array[wp.int32],
    ):
        env, lane = wp.tid()
        nb = wp.block_dim()
        off = env * n_nodes
        xs = wp.tile_load(x, shape=n_nodes, offset=off, storage="shared")
        vs = wp.tile_load(v, shape=n_nodes, offset=off, storage="shared")
        fs = wp.tile_zeros(shape=n_nodes, dtype=wp.vec3, storage="shared")
        mu = env_mu[env]
        lam = env_lam[env]
        zero = wp.vec3(0.0)
        for s in range(substeps):
            # elastic pass: colour by colour, one tet per lane, 4 non-atomic scatters (each a barrier)
            for c in range(n_colors):
                end = color_start[c + 1]
                for base in range(color_start[c], end, nb):
                    t = base + lane
                    i0 = int(0)
                    i1 = int(0)
                    i2 = int(0)
                    i3 = int(0)
                    g0 = zero
                    g1 = zero
                    g2 = zero
                    g3 = zero
                    h0 = False
                    h1 = False
                    h2 = False
                    h3 = False
                    if t < end:
                        i0 = tets[t, 0]
                        i1 = tets[t, 1]
                        i2 = tets[t, 2]
                        i3 = tets[t, 3]
                        g0, g1, g2 = tet_forces(xs[i0], xs[i1], xs[i2], xs[i3], vs[i0], vs[i1], vs[i2],
                                                vs[i3], dm_inv[t], mu, lam, alpha, beta)
                        g3 = -(g0 + g1 + g2)
                        h0 = need[i0] != 0
                        h1 = need[i1] != 0
                        h2 = need[i2] != 0
                        h3 = need[i3] != 0
                    wp.tile_scatter_add(fs, i0, g0, h0, atomic=False)
                    wp.tile_scatter_add(fs, i1, g1, h1, atomic=False)
                    wp.tile_scatter_add(fs, i2, g2, h2, atomic=False)
                    wp.tile_scatter_add(fs, i3, g3, h3, atomic=False)
            # node pass: integrate_contact_nodes' arithmetic, one node per lane; clears f
            for base in range(0, n_nodes, nb):
                node = base + lane
                has = node < n_nodes
                vel = zero
                xn = zero
                if has:
                    w = dt * inv_mass[node]
                    vel = vs[node] + w * fs[node]
                    xi = xs[node]
                    vel = contact_and_control(xi, vel, w, env, node, off + node, s == substeps - 1, fixed,
                                              on_surface, p, v_ctl, f_c, contact_flag)
                    xn = xi + dt * vel
                wp.tile_scatter_masked(vs, node, vel, has)
                wp.tile_scatter_masked(xs, node, xn, has)
                wp.tile_scatter_masked(fs, node, zero, has)
        wp.tile_store(x, xs, offset=off)
        wp.tile_store(v, vs, offset=off)

    return frame_resident


class ResidentLayout:
    """Device arrays of the resident kernel for one mesh: coloured moving tets, Dm^-1, node masks.

    `variant` (twin.integrator.resident_variant) picks the kernel: "tiles" (resident_kernel, a
    barrier per tile write), or "onesync", "packed", "atomic", "compact", "compact_atomic"
    (twin/resident_sync.py)."""

    def __init__(self, tets: np.ndarray, dm_inv: np.ndarray, needs_force: np.ndarray, device,
                 colored: bool = True, cap: int | None = None, variant: str = "tiles",
                 coloring: str = "mesh_order", shell: np.ndarray | None = None):
        if variant not in VARIANTS:
            raise ValueError(f"twin.integrator.resident_variant={variant!r}: use one of {VARIANTS}")
        if shell is not None and variant not in LAYERED_VARIANTS:
            raise ValueError(f"twin.integrator.resident_variant={variant!r} has no layered elastic kernel: use "
                             f"one of {LAYERED_VARIANTS} or twin.integrator.kernel='streamed'")
        # colored=False: one "colour" in mesh order, the streamed path's sum order; valid with one
        # lane per block only (the CPU default), where it reproduces the streamed kernels bit for bit.
        order, start = (color_tets(tets, needs_force, cap, coloring) if colored
                        else (np.arange(len(tets)), [0, len(tets)]))
        start = np.asarray(start, np.int32)
        atomic = variant in ("atomic", "compact_atomic")
        if atomic:  # colour order (a warp's tets rarely share a node, so its atomics rarely
            start = start[[0, -1]]  # collide), full chunks across colours: no barrier between them
        self.variant = variant
        self.block_dim = cap or 1  # the launch's threads a block: a colour fills at most one block's lanes
        self.n_colors = len(start) - 1
        self.n_tets = len(order)
        self.need = wp.array(needs_force.astype(np.int32), dtype=wp.int32, device=device)
        n_nodes = len(needs_force)
        if variant in ("tiles", "onesync"):
            self.tets = wp.array(tets[order].astype(np.int32), dtype=wp.int32, device=device)
            self.dm_inv = wp.array(dm_inv[order], dtype=wp.mat33, device=device)
            self.color_start = wp.array(start, dtype=wp.int32, device=device)
            self.kernel = resident_kernel(n_nodes) if variant == "tiles" else onesync_kernel(n_nodes)
        else:  # packed constants over a flat chunk table (one chunk: at most one tet a lane, one colour)
            self.lanes = block_lanes(device, cap or 1)
            cs, ce = chunk_table(start, self.lanes)
            self.n_chunks = len(cs) - 1
            self.chunk_start = wp.array(cs, dtype=wp.int32, device=device)
            self.chunk_end = wp.array(ce, dtype=wp.int32, device=device)
            # "compact": nodes renumbered force nodes first, so the force tile covers those only
            n_force = int(needs_force.sum()) if variant.startswith("compact") else 0
            to_global = (np.concatenate([np.flatnonzero(needs_force), np.flatnonzero(~needs_force)])
                         if n_force else np.arange(n_nodes))
            to_local = np.argsort(to_global)
            self.local_to_global = wp.array(to_global.astype(np.int32), dtype=wp.int32, device=device)
            self.corners = wp.array(pack_corners(to_local[tets[order]], needs_force[to_global]), dtype=wp.uint64,
                                    device=device)
            rows = np.ascontiguousarray(dm_inv[order].reshape(len(order), 9).T, dtype=np.float32)
            self.dm_rows = wp.array(rows, dtype=float, device=device)
            bounds = (cap or 512, 2) if n_force else (512, 1)  # compact: registers for two blocks an SM
            # layered (residual loop): each tet's shell fraction, in the chunks' tet order like Dm^-1
            self.shell = wp.array(np.zeros(1) if shell is None else np.asarray(shell)[order], dtype=float,
                                  device=device)
            self.layered = shell is not None
            self.kernel = packed_kernel(n_nodes, atomic, n_force, bounds, self.layered)

    @classmethod
    def for_mesh(cls, mesh, needs_force: np.ndarray, device, colored: bool = True, cap: int | None = None,
                 variant: str = "tiles", coloring: str = "mesh_order",
                 tet_shell: np.ndarray | None = None) -> "ResidentLayout":
        """The layout of the tets with a node that needs its force (the streamed kernels' moving tets);
        `cap` = the block size: colours of at most one chunk each; `tet_shell` (per mesh tet) selects
        the layered elastic kernel."""
        moving = needs_force[mesh.tets].any(axis=1)
        tets = mesh.tets[moving]
        return cls(tets, rest_shape(mesh.nodes, tets)[0], needs_force, device, colored, cap, variant, coloring,
                   None if tet_shell is None else np.asarray(tet_shell)[moving])

    def constants(self, lanes: int) -> list:
        """The kernel's mesh-constant arguments (before inv_mass) for blocks of `lanes` threads."""
        if self.variant in ("tiles", "onesync"):
            return [self.tets, self.dm_inv, self.color_start, self.n_colors, self.need]
        if lanes != self.lanes:
            raise ValueError(f"resident_variant {self.variant}: the layout has chunks for {self.lanes} lanes, "
                             f"the launch {lanes}; build the twin after setting wp.config.enable_cpu_blocks")
        return [self.corners, self.dm_rows, self.chunk_start, self.chunk_end, self.n_chunks]

    def extra_args(self, sim) -> list:
        """The packed kernels' last arguments: their node numbering (identity unless "compact*") and
        the layered kernel's shell fractions, shell ratios and alphas (read only when layered)."""
        if self.variant in ("tiles", "onesync"):
            return []
        per_env = [sim.env_shell_ratio, sim.env_alpha] if self.layered else [self.shell, self.shell]
        return [self.local_to_global, self.shell, *per_env]


def block_lanes(device, block_dim: int) -> int:
    """Threads a block of `wp.launch_tiled` gets: one on the CPU unless cooperative CPU blocks are on."""
    return block_dim if wp.get_device(device).is_cuda or wp.config.enable_cpu_blocks else 1


def launch_resident(sim) -> None:
    """All substeps of one frame of `sim` (a BatchedTwin) in one launch: one block per env."""
    lay, d = sim.resident, sim.cfg.damping
    block_dim = lay.block_dim
    consts = lay.constants(block_lanes(sim.device, block_dim))
    wp.launch_tiled(lay.kernel, dim=[sim.n_envs], block_dim=block_dim, device=sim.device,
                    inputs=[*consts, sim.inv_mass, sim.fixed, sim.on_surface, sim.env_mu, sim.env_lam,
                            d.alpha, d.beta, sim.dt, sim.substeps, sim.contact, sim.v_ctl],
                    outputs=[sim.x, sim.v, sim.f_c, sim.contact_flag, *lay.extra_args(sim)])


def _cpu_auto(sim) -> bool:
    """Whether `sim` runs the CPU's auto layout (one lane in mesh order: the streamed kernels' bits)."""
    return sim.resident is not None and not sim.device.is_cuda and sim.cfg.integrator.kernel == "auto"


def frame_kernels(sim) -> tuple[bool, ...]:
    """The kernels that may run a frame of `sim` (True: resident): both under auto on the CPU (frame_kernel's
    fallback), else the one it was built for."""
    return (True, False) if _cpu_auto(sim) else (sim.resident is not None,)


@contextmanager
def frame_kernel(sim) -> Iterator[bool]:
    """Yields whether the next frame of `sim` runs the resident kernel, holding CPU_TILES_LOCK for it on the CPU.
    Under auto a CPU frame that would wait for the lock runs the streamed kernels instead: the same bits, and a
    process's worker threads keep every core."""
    if sim.resident is None or sim.device.is_cuda:
        yield sim.resident is not None
    elif CPU_TILES_LOCK.acquire(blocking=not _cpu_auto(sim)):
        try:
            yield True
        finally:
            CPU_TILES_LOCK.release()
    else:
        yield False


def resident_shared_bytes(variant: str, n_nodes: int, n_force: int) -> int:
    """Shared memory of one env block: x, v over all nodes, f over the force nodes ("compact*") or all."""
    return (2 * n_nodes + (n_force if variant.startswith("compact") else n_nodes)) * VEC3


def runs_resident(cfg, needs_force: np.ndarray, device, n_envs: int) -> bool:
    """Whether `cfg.integrator.kernel` selects the frame-resident kernel for `n_envs` envs on `device`.

    "auto" (SDF contact only): on CUDA where the config allows it (the layered elastic kernel only in the
    packed variants), for batches of at least `auto_min_envs` envs, and where an env's tiles fit one block's
    shared memory (plus 4 KB of static shared memory). On the CPU for any batch whose tiles fit Warp's CPU
    block (CPU_AUTO: one lane in mesh order, the streamed kernels' bits). Else the streamed kernels."""
    ig = cfg.integrator
    if ig.kernel != "auto":
        return ig.kernel == "resident"
    dev = wp.get_device(device)
    n = len(needs_force)
    if cfg.contact.rule != "sdf":
        return False
    if not dev.is_cuda:
        return n < NEED_BIT and resident_shared_bytes(CPU_AUTO, n, int(needs_force.sum())) <= CPU_SHARED_BYTES
    if n_envs < ig.auto_min_envs or (cfg.layered and ig.resident_variant not in LAYERED_VARIANTS):
        return False
    if ig.resident_variant not in ("tiles", "onesync") and n >= NEED_BIT:  # 15-bit packed corner indices
        return False
    return resident_shared_bytes(ig.resident_variant, n, int(needs_force.sum())) + 4096 <= \
        dev.max_shared_memory_per_block


def resident_layout(mesh, needs_force: np.ndarray, device, cfg, n_envs: int, shell: np.ndarray):
    """The resident kernel's layout for a twin of `cfg` (None where `runs_resident` says streamed), built once per
    mesh and setting (the residual loop builds a twin per call; the colouring costs ~0.3 s at reference).
    `shell`: per mesh tet shell fractions, used with the layered elastic kernel."""
    if not runs_resident(cfg, needs_force, device, n_envs):
        return None
    ig = cfg.integrator
    tet_shell = shell if cfg.layered else None
    if ig.kernel == "auto" and not wp.get_device(device).is_cuda:  # one lane in mesh order: no colours needed
        return per_mesh(mesh, ("resident", str(device), CPU_AUTO, cfg.layered, cfg.material.shell_thickness),
                        lambda: ResidentLayout.for_mesh(mesh, needs_force, device, colored=False, variant=CPU_AUTO,
                                                        tet_shell=tet_shell))
    key = ("resident", str(device), block_lanes(device, ig.block_dim), ig.block_dim, ig.resident_variant,
           ig.resident_coloring, cfg.layered, cfg.material.shell_thickness)
    return per_mesh(mesh, key, lambda: ResidentLayout.for_mesh(
        mesh, needs_force, device, cap=ig.block_dim, variant=ig.resident_variant, coloring=ig.resident_coloring,
        tet_shell=tet_shell))
