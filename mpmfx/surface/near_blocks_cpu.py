"""sparse_kernels.mark_near_blocks on the CPU, a block of particles per thread.

mark_near_blocks takes a particle per thread and tests every block within reach of it (at
"fine" 13 voxels: up to 64 blocks for each of 100k particles, 20-35 ms on one thread). Most of
those answers follow from where the particle's block lies: the particles binned in the gather
cells of block C (cells 2C, 2C + 1 along each axis, sparse.CELLS_PER_BLOCK = 2) lie in the
voxel span [8 C, 8 C + 8), so a block B whose voxels [8 B, 8 B + 7] are within reach of every
point of that span is near as soon as C holds a particle, and one out of reach of every point
is never marked from C. Only the blocks in between test C's particles, with
mark_near_blocks' own float32 arithmetic and candidate range, and stop at the first that
reaches. The bounds are taken in float64 with a margin of 1e-4 r^2, far wider than float32's
rounding of the distances (a few 1e-7 r^2), so `near` is mark_near_blocks' bit for bit.

Two launches: the certain marks first, so the particle tests run only for blocks still
unmarked (the outer shell of the near set). Threads write only 1s: any interleaving agrees.
"""

import warp as wp

from mpmfx.surface.sparse_kernels import BS

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


@wp.kernel
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


@wp.kernel
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
    positions in the cells' order (gs[k] = g[order[k]], sparse._sorted_positions), so a cell's
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
                                if int(wp.floor((gp[a] - reach) / 8.0)) > b[a] or int(wp.floor((gp[a] + reach) / 8.0)) < b[a]:
                                    inside = 0
                                e = wp.max(wp.max(float(b[a] * BS) - gp[a], gp[a] - float(b[a] * BS + BS - 1)), 0.0)
                                d2 += e * e
                            if inside != 0 and d2 <= r2:
                                hit = 1
                if hit != 0:
                    near[bi, bj, bk] = 1
