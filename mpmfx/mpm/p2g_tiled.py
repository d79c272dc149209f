"""Phase 2, tiled: P2G accumulated per brick of cells in shared memory, one global add per node.

The reference P2G (p2g.py) adds each particle's 27 x 4 contributions with global atomics;
at 8 particles per cell those atomics are most of a substep on a GPU. Here (fast mode, no
multi-field contact):

    1. key = the brick (BRICK^3 cells) holding the particle's base node;
    2. particles sorted by key (radix sort of (key, index), every substep: they move), and
       their mass, momentum, MLS affine term and stencil offset gathered in sorted order
       (the binned P2G's payload kernel, p2g_binned.py);
    3. one thread block per occupied brick: its threads take the brick's particles in turns
       and add their contributions into a shared-memory tile of the brick's
       (BRICK + 2)^3 nodes (`wp.tile_scatter_add`: shared atomics);
    4. the block adds the tile's non-zero nodes to the grid: one global atomic per node and
       channel instead of one per particle, node and channel.

The float sums are ordered differently from the reference's (whose atomics have no order
either), so results agree within float rounding, not bit for bit. Extra device memory: the
binned P2G's 92 bytes per particle.
"""

from __future__ import annotations

import functools

import warp as wp

from .p2g import P2GParams
from .p2g_binned import NO_KEY, BinnedP2G, _starts
from .constitutive import bspline_weights
from .state import SceneFlags
from .stepper import SubstepDev

__all__ = ["TiledP2G"]

BRICK = wp.constant(4)  # cells per brick edge
SPAN = wp.constant(6)  # nodes per tile edge: BRICK + the stencil's 2
TILE_NODES = wp.constant(216)  # SPAN^3
BLOCK_DIM = 128  # threads per brick


@wp.kernel(enable_backward=False)
def _brick_keys(pp: P2GParams, x: wp.array(dtype=wp.vec3), alive: wp.array(dtype=wp.int32),
                mass: wp.array(dtype=float), bricks: int, keys: wp.array(dtype=wp.int32),
                idx: wp.array(dtype=wp.int32), n_runs: wp.array(dtype=wp.int32), sub: wp.array(dtype=SubstepDev)):
    p = wp.tid()
    if sub[0].active == 0:
        return
    if p == 0:
        n_runs[0] = 0
    idx[p] = p
    if alive[p] == 0 or mass[p] == 0.0:
        keys[p] = NO_KEY
        return
    xg = x[p] * pp.inv_dx
    bi = int(wp.floor(xg[0] - 0.5)) // BRICK
    bj = int(wp.floor(xg[1] - 0.5)) // BRICK
    bk = int(wp.floor(xg[2] - 0.5)) // BRICK
    keys[p] = (bi * bricks + bj) * bricks + bk


@wp.kernel(enable_backward=False)
def _tiled_scatter(pp: P2GParams, bricks: int, keys: wp.array(dtype=wp.int32), idx: wp.array(dtype=wp.int32),
                   start: wp.array(dtype=wp.int32), n_runs: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec3),
                   px: wp.array(dtype=wp.vec3), pm: wp.array(dtype=float), pmv: wp.array(dtype=wp.vec3),
                   paff: wp.array(dtype=wp.mat33), grid_m: wp.array3d(dtype=float),
                   grid_mv: wp.array3d(dtype=wp.vec3), sub: wp.array(dtype=SubstepDev)):
    r, lane = wp.tid()
    if sub[0].active == 0 or r >= n_runs[0]:
        return  # the whole block: r is the block's index
    s0 = start[r]
    s1 = start[r + 1]
    key = keys[s0]
    b0 = (key // (bricks * bricks)) * BRICK  # the brick's first node
    b1 = ((key // bricks) % bricks) * BRICK
    b2 = (key % bricks) * BRICK
    nb = wp.block_dim()
    dx = 1.0 / pp.inv_dx
    tile = wp.tile_zeros(shape=TILE_NODES, dtype=wp.vec4, storage="shared")
    for first in range(s0, s1, nb):  # the brick's particles, a block's width at a time
        s = first + lane
        has = s < s1
        fx = wp.vec3(1.0)
        m = float(0.0)
        mv = wp.vec3(0.0)
        aff = wp.mat33(0.0)
        o = wp.vec3i(0, 0, 0)
        if has:
            fx = px[s]  # the payload's offset from the base node, as the reference computes it
            m = pm[s]
            mv = pmv[s]
            aff = paff[s]
            xg = x[idx[s]] * pp.inv_dx
            o = wp.vec3i(int(wp.floor(xg[0] - 0.5)) - b0, int(wp.floor(xg[1] - 0.5)) - b1,
                         int(wp.floor(xg[2] - 0.5)) - b2)
        W = bspline_weights(fx)
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    w = W[i, 0] * W[j, 1] * W[k, 2]
                    dpos = (wp.vec3(float(i), float(j), float(k)) - fx) * dx
                    mom = w * (mv + aff * dpos)
                    t = ((o[0] + i) * SPAN + o[1] + j) * SPAN + o[2] + k
                    wp.tile_scatter_add(tile, t, wp.vec4(w * m, mom[0], mom[1], mom[2]), has)
    nn = pp.nodes
    for t in range(lane, TILE_NODES, nb):
        v = tile[t]
        if v[0] != 0.0:
            i = b0 + t // (SPAN * SPAN)
            j = b1 + (t // SPAN) % SPAN
            k = b2 + t % SPAN
            if i < nn and j < nn and k < nn:
                wp.atomic_add(grid_m, i, j, k, v[0])
                wp.atomic_add(grid_mv, i, j, k, wp.vec3(v[1], v[2], v[3]))


class TiledP2G(BinnedP2G):
    """The binned P2G's buffers and payload, keyed by brick, scattered per brick in shared
    memory. Fast mode only (float tile); multi-field scenes use the reference P2G."""

    def __init__(self, flags: SceneFlags, n: int, device, nodes: int):
        super().__init__(flags, n, device)
        self.bricks = (nodes + BRICK - 1) // BRICK

    def launch(self, pp: P2GParams, state, cur, materials, grid_m, grid_mv, grid_fixed, sub) -> None:
        n, dev = self.n, self.device
        wp.launch(_brick_keys, dim=n, device=dev, inputs=[pp, cur.x, cur.alive, state.mass, self.bricks, self.keys,
                                                           self.idx, self.n_runs, sub])
        wp.utils.radix_sort_pairs(self.keys, self.idx, n)
        wp.launch(self.payload, dim=n, device=dev, inputs=[
            pp, self.keys, self.idx, cur.x, cur.v, cur.C, cur.F, cur.J, cur.Jp, state.mass, state.volume,
            state.material, materials, self.px, self.pm, self.pmv, self.paff, self.flag, sub])
        wp.utils.array_scan(self.flag, self.pos, inclusive=False)
        wp.launch(_starts, dim=n, device=dev, inputs=[self.keys, self.flag, self.pos, n, self.start, self.n_runs, sub])
        # one block per brick that can hold particles; blocks past n_runs return at once
        wp.launch_tiled(_tiled_scatter, dim=[min(n, self.bricks ** 3)], block_dim=BLOCK_DIM, device=dev, inputs=[
            pp, self.bricks, self.keys, self.idx, self.start, self.n_runs, cur.x, self.px, self.pm, self.pmv,
            self.paff, grid_m, grid_mv, sub])
