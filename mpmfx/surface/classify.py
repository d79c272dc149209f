"""Block pass: the blocks' classes, OUTSIDE, INSIDE or ACTIVE, and the active blocks' list.

A block is OUTSIDE when no particle lies within SparseGrid.reach_vox of it, INSIDE when it and
its neighbours are dense (SparseGrid's dense rule), else ACTIVE. OUTSIDE blocks the grid
boundary does not reach (voids) become ACTIVE next to other blocks and INSIDE within, until the
voxels' topology tells a bubble from the open space between sparse particles (settle_voids,
open_voids).

The near blocks: GPU, a particle per thread tests every block within reach of it
(mark_near_blocks); CPU, a block of particles per thread (mark_near_certain, mark_near_tested).
Most of those answers follow from where the particle's block lies: the particles binned in the
gather cells of block C lie in the voxel span [8 C, 8 C + 8), so a block B whose voxels
[8 B, 8 B + 7] are within reach of every point of that span is near as soon as C holds a
particle, and one out of reach of every point is never marked from C. Only the blocks in
between test C's particles, with mark_near_blocks' own float32 arithmetic and candidate range,
and stop at the first that reaches. The bounds are taken in float64 with a margin of 1e-4 r^2,
far wider than float32's rounding of the distances (a few 1e-7 r^2), so `near` is
mark_near_blocks' bit for bit. The certain marks come first, so the particle tests run only for
blocks still unmarked. Threads write only 1s: any interleaving agrees.
"""

from __future__ import annotations

import logging
import math

import warp as wp

from mpmfx.surface.grid import SparseGrid
from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import launch_split, scan, split
from mpmfx.surface.voxels import BS, BV, LABEL_BIG, LABEL_NONE, TILE_ACTIVE, TILE_INSIDE, TILE_OUTSIDE

log = logging.getLogger(__name__)

MAX_BLOCK_SWEEP_ROUNDS = 256  # block-grid flood fill (a full line per launch: settles in a few rounds)

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


@wp.kernel
def mark_near_blocks(g: wp.array(dtype=wp.vec3), reach: float, near: wp.array3d(dtype=wp.int32), base: int):
    """near = 1 on blocks with a voxel within `reach` voxels of a particle (box distance)."""
    p = wp.tid() + base
    gp = g[p]
    lo = wp.vec3i(0)
    hi = wp.vec3i(0)
    for a in range(3):
        lo[a] = wp.max(int(wp.floor((gp[a] - reach) / 8.0)), 0)
        hi[a] = wp.min(int(wp.floor((gp[a] + reach) / 8.0)), near.shape[a] - 1)
    r2 = reach * reach
    for bi in range(lo[0], hi[0] + 1):
        for bj in range(lo[1], hi[1] + 1):
            for bk in range(lo[2], hi[2] + 1):
                if near[bi, bj, bk] == 0:  # most blocks are marked already by a particle before
                    b = wp.vec3i(bi, bj, bk)
                    d2 = float(0.0)
                    for a in range(3):
                        # distance from the particle to the block's voxel span [8 b, 8 b + 7]
                        e = wp.max(wp.max(float(b[a] * BS) - gp[a], gp[a] - float(b[a] * BS + BS - 1)), 0.0)
                        d2 += e * e
                    if d2 <= r2:
                        near[bi, bj, bk] = 1


@wp.kernel
def classify_blocks(
    counts: wp.array3d(dtype=wp.int32),
    near: wp.array3d(dtype=wp.int32),
    dense_reach: int,
    dense_min: int,
    state: wp.array3d(dtype=wp.int32),
):
    """OUTSIDE: no particle near; INSIDE: every block within `dense_reach` holds >= dense_min
    particles (the kernel support is then full, so the field is deep inside); else ACTIVE."""
    i, j, k = wp.tid()
    n = wp.vec3i(counts.shape[0], counts.shape[1], counts.shape[2])
    dense = int(1)
    for a in range(i - dense_reach, i + dense_reach + 1):
        for b in range(j - dense_reach, j + dense_reach + 1):
            for c in range(k - dense_reach, k + dense_reach + 1):
                cnt = int(0)
                if a >= 0 and b >= 0 and c >= 0 and a < n[0] and b < n[1] and c < n[2]:
                    cnt = counts[a, b, c]
                if cnt < dense_min:
                    dense = 0
    s = TILE_ACTIVE
    if near[i, j, k] == 0:
        s = TILE_OUTSIDE
    elif dense == 1:
        s = TILE_INSIDE
    state[i, j, k] = s


@wp.kernel
def outside_block_labels(state: wp.array3d(dtype=wp.int32), labels: wp.array3d(dtype=wp.int32)):
    """Flood-fill seeds over constant-outside blocks: label 0 on the grid's faces, the block's
    linear index + 1 elsewhere. After the sweeps (sweep_block_labels) the blocks the boundary
    reaches hold 0, and each void (the others) the least seed of its blocks: one label a void."""
    i, j, k = wp.tid()
    if state[i, j, k] == TILE_OUTSIDE:
        if i == 0 or j == 0 or k == 0 or i == state.shape[0] - 1 or j == state.shape[1] - 1 or k == state.shape[2] - 1:
            labels[i, j, k] = 0
        else:
            labels[i, j, k] = (i * state.shape[1] + j) * state.shape[2] + k + 1
    else:
        labels[i, j, k] = LABEL_NONE


@wp.kernel
def sweep_block_labels(labels: wp.array3d(dtype=wp.int32), axis: int, reverse: int, changed: wp.array(dtype=wp.int32)):
    """Carry the minimum label along one line of the block grid through labelled blocks.

    Launched over the two other axes; six sweeps (+-x, +-y, +-z) repeated until nothing
    changes label every 6-connected component with its smallest seed (flood fill).
    """
    a, b = wp.tid()
    n = labels.shape[axis]
    carry = int(LABEL_BIG)
    count = int(0)
    for t in range(n):
        s = t
        if reverse != 0:
            s = n - 1 - t
        c = wp.vec3i(s, a, b)
        if axis == 1:
            c = wp.vec3i(a, s, b)
        elif axis == 2:
            c = wp.vec3i(a, b, s)
        lab = labels[c[0], c[1], c[2]]
        if lab == LABEL_NONE:
            carry = LABEL_BIG
        else:
            if carry < lab:
                labels[c[0], c[1], c[2]] = carry
                count += 1
            else:
                carry = lab
    if count > 0:
        changed[0] = 1  # a flag: every writer stores the same value, no atomic contention


@wp.kernel
def count_voids(labels: wp.array3d(dtype=wp.int32), count: wp.array(dtype=wp.int32)):
    """count[0] += the OUTSIDE blocks the grid boundary does not reach (labels above 0 after the
    block flood fill: voids). Most grids have none: no atomic contends."""
    i, j, k = wp.tid()
    if labels[i, j, k] > 0:
        wp.atomic_add(count, 0, 1)


@wp.kernel
def void_shells(labels: wp.array3d(dtype=wp.int32), state: wp.array3d(dtype=wp.int32)):
    """A void's blocks (labels above 0) next to (26-neighbourhood) a block of no void become
    ACTIVE (its shell); the others INSIDE for now (its core: open_voids)."""
    i, j, k = wp.tid()
    if labels[i, j, k] <= 0:
        return
    shell = int(0)
    for n in range(27):
        a = i + n // 9 - 1
        b = j + (n // 3) % 3 - 1
        c = k + n % 3 - 1
        if labels[a, b, c] <= 0:  # a void never touches the grid's faces: its neighbours are in the grid
            shell = 1
    state[i, j, k] = wp.where(shell != 0, TILE_ACTIVE, TILE_INSIDE)


@wp.kernel
def void_openness(
    labels: wp.array3d(dtype=wp.int32),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    open_: wp.array(dtype=wp.int32),
):
    """open_[a void's label] = 1 where a voxel of its shell is outside after the topology's
    bubble fill: the void joins the outside through gaps in its surface. A sealed void's shell
    is all inside then (filled as a bubble)."""
    i, j, k = wp.tid()
    lab = labels[i, j, k]
    if lab <= 0:
        return
    b = bmap[i, j, k]
    if b < 0:
        return
    for q in range(BV):
        if phi[b * BV + q] > 0.0:
            open_[lab] = 1
            return


@wp.kernel
def open_void_cores(
    labels: wp.array3d(dtype=wp.int32), open_: wp.array(dtype=wp.int32), bmap: wp.array3d(dtype=wp.int32)
):
    """A void's core (INSIDE tiles) becomes OUTSIDE where the void is open (void_openness)."""
    i, j, k = wp.tid()
    lab = labels[i, j, k]
    if lab > 0 and bmap[i, j, k] == TILE_INSIDE and open_[lab] != 0:
        bmap[i, j, k] = TILE_OUTSIDE


@wp.kernel
def compact_blocks(
    state: wp.array3d(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    bmap: wp.array3d(dtype=wp.int32),
    bcoord: wp.array(dtype=wp.vec3i),
):
    """bmap = active index (exclusive scan of ACTIVE flags) or a constant tile."""
    i, j, k = wp.tid()
    s = state[i, j, k]
    if s == TILE_ACTIVE:
        lin = (i * state.shape[1] + j) * state.shape[2] + k
        b = offsets[lin]
        bmap[i, j, k] = b
        bcoord[b] = wp.vec3i(i, j, k)
    else:
        bmap[i, j, k] = s


@wp.kernel
def active_flags(state: wp.array3d(dtype=wp.int32), flags: wp.array(dtype=wp.int32)):
    i, j, k = wp.tid()
    flags[(i * state.shape[1] + j) * state.shape[2] + k] = wp.where(state[i, j, k] == TILE_ACTIVE, 1, 0)


MARGIN = wp.constant(1.0e-4)  # x r^2: how far from the reach a bound must be to decide without the particles


@wp.func
def span_bounds(b: wp.vec3i, c: wp.vec3i):
    """(least, greatest) squared distance (float64, voxels^2) from a point of the span
    [8 c, 8 c + 8) to block b's voxels [8 b, 8 b + 7], per mark_near_blocks' box distance."""
    dmin = wp.float64(0.0)
    dmax = wp.float64(0.0)
    for a in range(3):
        lo = wp.float64(b[a] * BS)
        hi = wp.float64(b[a] * BS + BS - 1)
        p0 = wp.float64(c[a] * BS)
        p1 = wp.float64(c[a] * BS + BS)
        # the box distance along a is convex in the point: greatest at an end of the span
        e0 = wp.max(wp.max(lo - p0, p0 - hi), wp.float64(0.0))
        e1 = wp.max(wp.max(lo - p1, p1 - hi), wp.float64(0.0))
        emax = wp.max(e0, e1)
        emin = wp.max(wp.max(lo - p1, p0 - hi), wp.float64(0.0))
        dmin += emin * emin
        dmax += emax * emax
    return dmin, dmax


@wp.func
def span_count(cells: wp.array3d(dtype=wp.int32), c: wp.vec3i):
    """Particles in the 8 gather cells of block c."""
    n = int(0)
    for q in range(8):
        n += cells[2 * c[0] + q // 4, 2 * c[1] + (q // 2) % 2, 2 * c[2] + q % 2]
    return n


@wp.func
def block_of(near: wp.array3d(dtype=wp.int32), t: int):
    n1 = near.shape[1]
    n2 = near.shape[2]
    return wp.vec3i(t // (n1 * n2), (t // n2) % n1, t % n2)


@wp.func
def neighbour_range(near: wp.array3d(dtype=wp.int32), c: wp.vec3i, reach: float):
    """Blocks b that a point of c's span can lie within `reach` of (a superset: the gap to b is
    8 (c - b) - 7 below c, 8 (b - c) - 8 above)."""
    lo = wp.vec3i(0)
    hi = wp.vec3i(0)
    for a in range(3):
        lo[a] = wp.max(c[a] - 1 - int(reach / float(BS)), 0)
        hi[a] = wp.min(c[a] + 1 + int(reach / float(BS)), near.shape[a] - 1)
    return lo, hi


@cpu_kernel
def mark_near_certain(cells: wp.array3d(dtype=wp.int32), reach: float, near: wp.array3d(dtype=wp.int32), base: int):
    """near = 1 on the blocks within reach of every point of block c's span (thread = block c
    of the grid), where c holds a particle."""
    c = block_of(near, wp.tid() + base)
    if span_count(cells, c) == 0:
        return
    r2 = wp.float64(reach) * wp.float64(reach)
    lo, hi = neighbour_range(near, c, reach)
    for bi in range(lo[0], hi[0] + 1):
        for bj in range(lo[1], hi[1] + 1):
            for bk in range(lo[2], hi[2] + 1):
                dmin, dmax = span_bounds(wp.vec3i(bi, bj, bk), c)
                if dmax < r2 * (wp.float64(1.0) - wp.float64(MARGIN)):
                    near[bi, bj, bk] = 1


@cpu_kernel
def mark_near_tested(
    cells: wp.array3d(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    gs: wp.array(dtype=wp.vec3),
    reach: float,
    near: wp.array3d(dtype=wp.int32),
    base: int,
):
    """After mark_near_certain: the still unmarked blocks that only some points of block c's
    span reach (thread = block c of the grid), tested against c's particles as
    mark_near_blocks tests them (its candidate range, its float32 distance). gs: the grid
    positions in the cells' order (gs[k] = g[order[k]], binning.sorted_positions), so a cell's
    particles are read in memory order."""
    c = block_of(near, wp.tid() + base)
    if span_count(cells, c) == 0:
        return
    r2d = wp.float64(reach) * wp.float64(reach)
    r2 = reach * reach
    lo, hi = neighbour_range(near, c, reach)
    for bi in range(lo[0], hi[0] + 1):
        for bj in range(lo[1], hi[1] + 1):
            for bk in range(lo[2], hi[2] + 1):
                if near[bi, bj, bk] != 0:
                    continue
                b = wp.vec3i(bi, bj, bk)
                dmin, dmax = span_bounds(b, c)
                if dmin > r2d * (wp.float64(1.0) + wp.float64(MARGIN)):
                    continue
                hit = int(0)
                for q in range(8):
                    ci = 2 * c[0] + q // 4
                    cj = 2 * c[1] + (q // 2) % 2
                    ck = 2 * c[2] + q % 2
                    cnt = cells[ci, cj, ck]
                    s = starts[(ci * cells.shape[1] + cj) * cells.shape[2] + ck]
                    for k in range(s, s + cnt):
                        if hit == 0:
                            gp = gs[k]
                            inside = int(1)  # mark_near_blocks' candidate range of this particle
                            d2 = float(0.0)
                            for a in range(3):
                                if (
                                    int(wp.floor((gp[a] - reach) / 8.0)) > b[a]
                                    or int(wp.floor((gp[a] + reach) / 8.0)) < b[a]
                                ):
                                    inside = 0
                                e = wp.max(wp.max(float(b[a] * BS) - gp[a], gp[a] - float(b[a] * BS + BS - 1)), 0.0)
                                d2 += e * e
                            if inside != 0 and d2 <= r2:
                                hit = 1
                if hit != 0:
                    near[bi, bj, bk] = 1


def near_blocks_by_voxel(gs, cells, starts, grid: SparseGrid, near) -> None:
    """near (block grid, zeroed) = 1 where a particle lies within grid.reach_vox: a particle per thread."""
    split(wp, mark_near_blocks, gs.shape[0], [gs, grid.reach_vox, near])  # writes 1s: any interleaving agrees


def near_blocks_by_block(gs, cells, starts, grid: SparseGrid, near) -> None:
    """near_blocks_by_voxel' marks, a block of particles per thread, most blocks decided without their particles."""
    nb = math.prod(grid.nblocks)
    # a grid block per thread, much work for those holding particles: split however few the blocks
    kw = {"device": gs.device, "min_split": 1}
    launch_split(wp, mark_near_certain, nb, [cells, grid.reach_vox, near], **kw)
    launch_split(wp, mark_near_tested, nb, [cells, starts, gs, grid.reach_vox, near], **kw)


def classify(near_blocks, gs, counts, cells, starts, grid: SparseGrid):
    """(bmap: block -> active index or tile code, bcoord: (m,) vec3i active block coordinates,
    the block flood fill's labels where there are voids, else None: settle_voids);
    near_blocks: a variant's near_blocks_*; cells, starts: the gather cells' particles
    (mpmfx.surface.binning), gs: their grid positions in the cells' order."""
    near = wp.zeros(grid.nblocks, dtype=wp.int32)
    near_blocks(gs, cells, starts, grid, near)
    state = wp.empty(grid.nblocks, dtype=wp.int32)
    wp.launch(classify_blocks, grid.nblocks, inputs=[counts, near, grid.dense_reach, grid.dense_min, state])
    labels = wp.empty(grid.nblocks, dtype=wp.int32)
    wp.launch(outside_block_labels, grid.nblocks, inputs=[state, labels])
    sweep_labels(labels)
    voids = settle_voids(labels, state, grid)
    flags = wp.empty(math.prod(grid.nblocks), dtype=wp.int32)
    wp.launch(active_flags, grid.nblocks, inputs=[state, flags])
    offsets = scan(wp, flags, inclusive=False)
    nact = int(offsets[-1:].numpy()[0] + flags[-1:].numpy()[0])
    bmap = wp.empty(grid.nblocks, dtype=wp.int32)
    bcoord = wp.empty(max(nact, 1), dtype=wp.vec3i)
    wp.launch(compact_blocks, grid.nblocks, inputs=[state, offsets, bmap, bcoord])
    return bmap, bcoord[:nact], voids


def settle_voids(labels, state, grid: SparseGrid):
    """Voids, the OUTSIDE blocks the grid boundary does not reach (`labels` above 0, one label a
    void), may be sealed air (a bubble in a body, a hollow shell's cavity: filled) or the open
    space between sparse particles (spray, open through gaps narrower than a block). The voxels
    tell them apart, so each void's blocks next to any other block (its shell) become ACTIVE,
    and the rest (its core) an INSIDE tile, until open_voids reads the shell after the bubble
    fill. As INSIDE tiles whole, an open void would be a phantom body (drops on a sphere, a
    ball among them: test_sparse); made ACTIVE whole, a void would cost in proportion to its
    volume, its shell costs in proportion to its area. Returns `labels` where there are voids,
    else None; `state` is updated in place."""
    count = wp.zeros(1, dtype=wp.int32)
    wp.launch(count_voids, grid.nblocks, inputs=[labels, count])
    if int(count.numpy()[0]) == 0:
        return None
    wp.launch(void_shells, grid.nblocks, inputs=[labels, state])
    return labels


def open_voids(bmap, phi, voids) -> None:
    """After the bubble fill (mpmfx.surface.flood): the core of each void (`voids`: settle_voids'
    labels) whose shell holds an outside voxel (open: its air joins the outside) becomes
    OUTSIDE; a sealed void's core stays INSIDE, as its shell was filled."""
    open_ = wp.zeros(math.prod(bmap.shape) + 1, dtype=wp.int32)  # by label: a block's linear index + 1
    wp.launch(void_openness, bmap.shape, inputs=[voids, bmap, phi, open_])
    wp.launch(open_void_cores, bmap.shape, inputs=[voids, open_, bmap])


def sweep_labels(labels) -> int:
    """Run +-x, +-y, +-z label sweeps over the block grid until no label changes; returns the
    rounds used."""
    changed = wp.zeros(1, dtype=wp.int32)
    n = labels.shape
    for rounds in range(1, MAX_BLOCK_SWEEP_ROUNDS + 1):
        changed.zero_()
        for axis in range(3):
            others = tuple(n[a] for a in range(3) if a != axis)
            for rev in (0, 1):
                wp.launch(sweep_block_labels, others, inputs=[labels, axis, rev, changed])
        if int(changed.numpy()[0]) == 0:
            return rounds
    log.warning("block label sweeps did not settle in %d rounds; some voids may remain", MAX_BLOCK_SWEEP_ROUNDS)
    return MAX_BLOCK_SWEEP_ROUNDS
