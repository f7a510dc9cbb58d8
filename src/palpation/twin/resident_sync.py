"""Frame-resident kernel variants with explicit block barriers (issue 17, `integrator.resident_variant`).

The present kernel (`resident.resident_kernel`, variant "tiles") syncs the block after each of its
4 corner scatters per colour chunk and after each of 3 node-pass writes: 4 x 44 + 3 x 7 = 197
barriers a substep at 512 threads. Only 2 kinds of barrier are needed: one after each colour chunk
(the next colour may touch the same nodes) and one after the node pass (the next substep reads
other lanes' x, v). Warp 1.19 has no barrier builtin, but `wp.func_native` snippets may sync and
write shared tiles directly, so these kernels keep exactly those barriers:

* "onesync": the present kernel with plain (unsynced) shared adds and one barrier per chunk, one
  after the node pass: 45 barriers a substep; the same adds in the same order, so the same bits.
* "packed": "onesync" plus mesh constants laid out for coalesced loads (the 4 corner indices and
  their need-force bits in one uint64, Dm^-1 as 9 rows of the tets) over a flat chunk table, and the
  next chunk's constants loaded before this chunk's forces (their L2 latency hides behind the
  arithmetic). The same float32 values and sums: the same bits as "tiles" with the same colouring.
* "atomic": "packed" with shared-memory float atomics and one barrier after the elastic pass: the
  tets in colour order (a warp's 32 tets rarely share a node, so its atomics rarely collide) but cut
  into full chunks across colours, 27 at reference instead of 44. Sum order follows the GPU's
  atomics, so CUDA runs are not bit-reproducible (rounding only); one CPU lane sums in colour order
  (the bits of "tiles" with one lane).
* "compact": "packed" with the nodes renumbered force nodes first, so the force tile holds only the
  force nodes (reference: x, v, f = 111,200 B instead of 123,696): two blocks of <= 384 threads fit
  an H100/H200 SM (launch bounds cap the registers), and one block's barriers no longer idle it.
  The same bits as "packed". "compact_atomic": "compact" with the atomics of "atomic".

The packed kernels (packed, atomic, compact, compact_atomic) also run the layered elastic kernel of the
residual loop (`layered`: per-tet shell fraction, per-env shell ratio and alpha) through the streamed
layered kernel's own per-tet function, `layered_tet_forces`.
"""

# no `from __future__ import annotations`: the tile annotations of the native helpers name closure
# variables (n_nodes), which Warp resolves only when they are evaluated at definition

import functools

import numpy as np
import warp as wp

from palpation.twin.contact import ContactParams, surface_contact_force
from palpation.twin.elasticity import layered_tet_forces, tet_forces

INDEX_BITS = 15  # per corner: a node index below 2**15 and its need-force bit
NEED_BIT = 1 << INDEX_BITS


@wp.func_native("WP_TILE_SYNC();")
def block_sync(): ...


def pack_corners(tets: np.ndarray, needs_force: np.ndarray) -> np.ndarray:
    """One uint64 a tet: corner k's node index in bits 16k..16k+14, its need-force flag in bit 16k+15."""
    tets = np.asarray(tets, np.int64)
    if tets.size and tets.max() >= NEED_BIT:
        raise ValueError(f"resident_variant packed/atomic/compact: {tets.max() + 1} nodes exceed the {NEED_BIT} "
                         "that a 16-bit corner field holds; use integrator.resident_variant='onesync'")
    fields = (tets | np.where(needs_force[tets], NEED_BIT, 0)).astype(np.uint64)
    return (fields[:, 0] | fields[:, 1] << np.uint64(16) | fields[:, 2] << np.uint64(32)
            | fields[:, 3] << np.uint64(48))


def chunk_table(color_start: np.ndarray, cap: int) -> tuple[np.ndarray, np.ndarray]:
    """(start, end) of every chunk of at most `cap` tets inside one colour, plus an empty sentinel."""
    starts, ends = [], []
    for a, b in zip(color_start[:-1], color_start[1:]):
        for s in range(int(a), int(b), cap):
            starts.append(s)
            ends.append(min(s + cap, int(b)))
    return np.array(starts + [0], np.int32), np.array(ends + [0], np.int32)


@functools.lru_cache(maxsize=None)
def tile_writers(n_nodes: int):
    """Unsynced per-lane writes into a (n_nodes,) vec3 shared tile: plain add, atomic add, store."""

    @wp.func_native("if (has) t.data(wp::tile_coord(i)) += value;")
    def add_plain(t: wp.tile[wp.vec3, n_nodes], i: int, value: wp.vec3, has: bool): ...

    @wp.func_native("if (has) wp::tile_atomic_add_value(&t.data(wp::tile_coord(i)), value);")
    def add_atomic(t: wp.tile[wp.vec3, n_nodes], i: int, value: wp.vec3, has: bool): ...

    @wp.func_native("if (has) t.data(wp::tile_coord(i)) = value;")
    def store(t: wp.tile[wp.vec3, n_nodes], i: int, value: wp.vec3, has: bool): ...

    return add_plain, add_atomic, store


@wp.func
def contact_and_control(xi: wp.vec3, vel: wp.vec3, w: float, env: int, node: int, slot: int, last: bool,
                        fixed: wp.array[wp.int32], on_surface: wp.array[wp.int32], p: ContactParams,
                        v_ctl: wp.array[wp.vec3], f_c: wp.array[wp.vec3], contact_flag: wp.array[wp.int32]):
    """A node's velocity after its elastic force, as integrate_contact_nodes does it: the surface contact (its force
    kept in f_c on the frame's last substep), then a driven node's control velocity. `slot`: the node's global index."""
    out = vel
    if on_surface[node] != 0:
        fc, touched = surface_contact_force(xi, vel, env, node, p, 1)
        if last:
            f_c[slot] = fc
        if touched != 0:
            contact_flag[env] = 1
        out = vel + w * fc
    if fixed[node] != 0:
        out = v_ctl[slot]
    return out


@functools.lru_cache(maxsize=None)
def node_pass(n_nodes: int):
    """The node pass of every variant here: integrate_contact_nodes' arithmetic, one node per lane,
    no barrier inside (each lane reads and writes its own nodes only); the caller syncs after it."""
    store = tile_writers(n_nodes)[2]

    @wp.func
    def nodes(lane: int, nb: int, env: int, off: int, s: int, substeps: int, dt: float, xs: wp.tile[wp.vec3, n_nodes],
              vs: wp.tile[wp.vec3, n_nodes], fs: wp.tile[wp.vec3, n_nodes], inv_mass: wp.array[float],
              fixed: wp.array[wp.int32], on_surface: wp.array[wp.int32], p: ContactParams,
              v_ctl: wp.array[wp.vec3], f_c: wp.array[wp.vec3], contact_flag: wp.array[wp.int32]):
        zero = wp.vec3(0.0)
        for base in range(0, n_nodes, nb):
            node = base + lane
            if node < n_nodes:
                w = dt * inv_mass[node]
                vel = vs[node] + w * fs[node]
                xi = xs[node]
                vel = contact_and_control(xi, vel, w, env, node, off + node, s == substeps - 1, fixed, on_surface, p,
                                          v_ctl, f_c, contact_flag)
                store(vs, node, vel, True)
                store(xs, node, xi + dt * vel, True)
                store(fs, node, zero, True)

    return nodes


@functools.lru_cache(maxsize=None)
def node_pass_compact(n_nodes: int, n_force: int):
    """`node_pass` over renumbered nodes: force nodes 0..n_force-1 (their f in a tile of n_force),
    then the driven interior ones, whose velocity the control sets (no force, no contact)."""
    store = tile_writers(n_nodes)[2]
    store_f = tile_writers(n_force)[2]

    @wp.func
    def nodes(lane: int, nb: int, env: int, off: int, s: int, substeps: int, dt: float, xs: wp.tile[wp.vec3, n_nodes],
              vs: wp.tile[wp.vec3, n_nodes], fs: wp.tile[wp.vec3, n_force], inv_mass: wp.array[float],
              fixed: wp.array[wp.int32], on_surface: wp.array[wp.int32], p: ContactParams,
              v_ctl: wp.array[wp.vec3], f_c: wp.array[wp.vec3], contact_flag: wp.array[wp.int32],
              local_to_global: wp.array[wp.int32]):
        for base in range(0, n_nodes, nb):
            i = base + lane
            if i < n_nodes:
                node = local_to_global[i]
                w = dt * inv_mass[node]
                vel = vs[i]
                if i < n_force:
                    vel = vel + w * fs[i]
                    store_f(fs, i, wp.vec3(0.0), True)
                xi = xs[i]
                vel = contact_and_control(xi, vel, w, env, node, off + node, s == substeps - 1, fixed, on_surface, p,
                                          v_ctl, f_c, contact_flag)
                store(vs, i, vel, True)
                store(xs, i, xi + dt * vel, True)

    return nodes


@functools.lru_cache(maxsize=None)
def onesync_kernel(n_nodes: int):
    """The "tiles" kernel's arithmetic and order with one barrier per colour chunk."""
    add_plain = tile_writers(n_nodes)[0]
    nodes = node_pass(n_nodes)

    @wp.kernel(enable_backward=False, module="unique", launch_bounds=512)
    def frame_onesync(tets: wp.array2d[wp.int32], dm_inv: wp.array[wp.mat33], color_start: wp.array[wp.int32],
                      n_colors: int, need: wp.array[wp.int32], inv_mass: wp.array[float],
                      fixed: wp.array[wp.int32], on_surface: wp.array[wp.int32], env_mu: wp.array[float],
                      env_lam: wp.array[float], alpha: float, beta: float, dt: float, substeps: int,
                      p: ContactParams, v_ctl: wp.array[wp.vec3], x: wp.array[wp.vec3], v: wp.array[wp.vec3],
                      f_c: wp.array[wp.vec3], contact_flag: wp.array[wp.int32]):
        env, lane = wp.tid()
        nb = wp.block_dim()
        off = env * n_nodes
        xs = wp.tile_load(x, shape=n_nodes, offset=off, storage="shared")
        vs = wp.tile_load(v, shape=n_nodes, offset=off, storage="shared")
        fs = wp.tile_zeros(shape=n_nodes, dtype=wp.vec3, storage="shared")
        mu = env_mu[env]
        lam = env_lam[env]
        for s in range(substeps):
            for c in range(n_colors):
                end = color_start[c + 1]
                for base in range(color_start[c], end, nb):
                    t = base + lane
                    if t < end:
                        i0 = tets[t, 0]
                        i1 = tets[t, 1]
                        i2 = tets[t, 2]
                        i3 = tets[t, 3]
                        g0, g1, g2 = tet_forces(xs[i0], xs[i1], xs[i2], xs[i3], vs[i0], vs[i1], vs[i2], vs[i3],
                                                dm_inv[t], mu, lam, alpha, beta)
                        add_plain(fs, i0, g0, need[i0] != 0)
                        add_plain(fs, i1, g1, need[i1] != 0)
                        add_plain(fs, i2, g2, need[i2] != 0)
                        add_plain(fs, i3, -(g0 + g1 + g2), need[i3] != 0)
                    block_sync()
            nodes(lane, nb, env, off, s, substeps, dt, xs, vs, fs, inv_mass, fixed, on_surface, p, v_ctl, f_c,
                  contact_flag)
            block_sync()
        wp.tile_store(x, xs, offset=off)
        wp.tile_store(v, vs, offset=off)

    return frame_onesync


@functools.lru_cache(maxsize=None)
def packed_kernel(n_nodes: int, atomic: bool, n_force: int = 0, bounds: tuple[int, int] = (512, 1),
                  layered: bool = False):
    """Packed constants, next chunk prefetched; colour chunks + plain adds, or mesh order + atomics.

    n_force > 0 ("compact"): the nodes are renumbered force nodes first (`local_to_global`), so the
    force tile holds the n_force nodes that need a force only. `bounds` = CUDA launch bounds (threads,
    blocks an SM): (block_dim, 2) caps the registers so that two blocks fit (65,536 / 2 / block_dim).
    layered: the streamed `eval_elastic_forces_layered`'s arithmetic (tet_shell in the chunks' tet order,
    env_shell_ratio and env_alpha per env); otherwise those three arrays are not read."""
    compact = n_force > 0
    n_f = n_force if compact else n_nodes
    add_plain, add_atomic = tile_writers(n_f)[:2]
    store = tile_writers(n_nodes)[2]
    nodes = node_pass_compact(n_nodes, n_force) if compact else node_pass(n_nodes)
    lo = wp.uint64(0x7FFF)

    @wp.func
    def corner(q: wp.uint64, k: int):
        f = (q >> wp.uint64(16 * k)) & wp.uint64(0xFFFF)
        return int(f & lo), (f >> wp.uint64(15)) != wp.uint64(0)

    @wp.func
    def load_dm(dm: wp.array2d[float], t: int):
        return wp.mat33(dm[0, t], dm[1, t], dm[2, t], dm[3, t], dm[4, t], dm[5, t], dm[6, t], dm[7, t], dm[8, t])

    @wp.kernel(enable_backward=False, module="unique", launch_bounds=bounds)
    def frame_packed(corners: wp.array[wp.uint64], dm: wp.array2d[float], chunk_start: wp.array[wp.int32],
                     chunk_end: wp.array[wp.int32], n_chunks: int, inv_mass: wp.array[float],
                     fixed: wp.array[wp.int32], on_surface: wp.array[wp.int32], env_mu: wp.array[float],
                     env_lam: wp.array[float], alpha: float, beta: float, dt: float, substeps: int,
                     p: ContactParams, v_ctl: wp.array[wp.vec3], x: wp.array[wp.vec3], v: wp.array[wp.vec3],
                     f_c: wp.array[wp.vec3], contact_flag: wp.array[wp.int32],
                     local_to_global: wp.array[wp.int32], tet_shell: wp.array[float],
                     env_shell_ratio: wp.array[float], env_alpha: wp.array[float]):
        env, lane = wp.tid()
        nb = wp.block_dim()
        off = env * n_nodes
        last = corners.shape[0] - 1
        if wp.static(compact):  # x, v in the kernel's node numbering
            xs = wp.tile_empty(shape=n_nodes, dtype=wp.vec3, storage="shared")
            vs = wp.tile_empty(shape=n_nodes, dtype=wp.vec3, storage="shared")
            for base in range(0, n_nodes, nb):
                i = base + lane
                if i < n_nodes:
                    store(xs, i, x[off + local_to_global[i]], True)
                    store(vs, i, v[off + local_to_global[i]], True)
        else:
            xs = wp.tile_load(x, shape=n_nodes, offset=off, storage="shared")
            vs = wp.tile_load(v, shape=n_nodes, offset=off, storage="shared")
        fs = wp.tile_zeros(shape=n_f, dtype=wp.vec3, storage="shared")
        block_sync()
        mu = env_mu[env]
        lam = env_lam[env]
        a = alpha
        ratio = float(1.0)
        if wp.static(layered):
            a = env_alpha[env]
            ratio = env_shell_ratio[env]
        for s in range(substeps):
            t = chunk_start[0] + lane
            ok = t < chunk_end[0]
            tc = wp.min(t, last)  # idle lanes load a valid tet and skip it
            q = corners[tc]
            B = load_dm(dm, tc)
            w = float(0.0)
            if wp.static(layered):
                w = tet_shell[tc]
            for k in range(n_chunks):
                # the next chunk's constants first (the sentinel after the last chunk is empty)
                tn = chunk_start[k + 1] + lane
                ok_n = tn < chunk_end[k + 1]
                tn = wp.min(tn, last)
                q_n = corners[tn]
                B_n = load_dm(dm, tn)
                w_n = float(0.0)
                if wp.static(layered):
                    w_n = tet_shell[tn]
                if ok:
                    i0, h0 = corner(q, 0)
                    i1, h1 = corner(q, 1)
                    i2, h2 = corner(q, 2)
                    i3, h3 = corner(q, 3)
                    if wp.static(layered):
                        g0, g1, g2 = layered_tet_forces(xs[i0], xs[i1], xs[i2], xs[i3], vs[i0], vs[i1], vs[i2],
                                                        vs[i3], B, mu, lam, ratio, w, a, beta)
                    else:
                        g0, g1, g2 = tet_forces(xs[i0], xs[i1], xs[i2], xs[i3], vs[i0], vs[i1], vs[i2], vs[i3], B,
                                                mu, lam, alpha, beta)
                    g3 = -(g0 + g1 + g2)
                    if wp.static(atomic):
                        add_atomic(fs, i0, g0, h0)
                        add_atomic(fs, i1, g1, h1)
                        add_atomic(fs, i2, g2, h2)
                        add_atomic(fs, i3, g3, h3)
                    else:
                        add_plain(fs, i0, g0, h0)
                        add_plain(fs, i1, g1, h1)
                        add_plain(fs, i2, g2, h2)
                        add_plain(fs, i3, g3, h3)
                if wp.static(not atomic):
                    block_sync()  # the next colour may share nodes with this one
                q = q_n
                B = B_n
                w = w_n
                ok = ok_n
            if wp.static(atomic):
                block_sync()
            if wp.static(compact):
                nodes(lane, nb, env, off, s, substeps, dt, xs, vs, fs, inv_mass, fixed, on_surface, p, v_ctl, f_c,
                      contact_flag, local_to_global)
            else:
                nodes(lane, nb, env, off, s, substeps, dt, xs, vs, fs, inv_mass, fixed, on_surface, p, v_ctl, f_c,
                      contact_flag)
            block_sync()
        if wp.static(compact):
            for base in range(0, n_nodes, nb):
                i = base + lane
                if i < n_nodes:
                    x[off + local_to_global[i]] = xs[i]
                    v[off + local_to_global[i]] = vs[i]
        else:
            wp.tile_store(x, xs, offset=off)
            wp.tile_store(v, vs, offset=off)

    return frame_packed
