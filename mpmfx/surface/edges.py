"""Edge pass: how far the smoothing may round each part of the surface (the same kernels
on every device).

The mean-curvature flow moves a convex edge inward wherever it runs, noise or not. Where the
samples are regular (a lattice, a freshly voxelised body) the raw field already holds the edge,
and the flow would only round it. So at an edge the flow may move the surface inward only as
far as the samples' own noise there, measured from the particles: the kernel centroid's offset
along the edge, which a regular sampling keeps at ~0 and random samples do not.

An edge is told from noise at the wide normal's scale (the blurred weights, mpmfx.surface.field):
their level set curves sharply only at features under a few particle spacings across, however
noisy the samples. Lengths are voxels; arrays are over the active voxels (or blocks) as in
:mod:`mpmfx.surface.voxels`.
"""

import warp as wp

from mpmfx.surface.grid import SparseGrid
from mpmfx.surface.launch import split
from mpmfx.surface.voxels import BS, BV, in_block, slot, voxel_of, weight_at

# forward only: nothing differentiates these kernels; their adjoint code would only lengthen the compile
wp.set_module_options({"enable_backward": False})

EDGE_CURVATURE = (0.35, 0.5)  # x 1 / the wide normal's blur width: a convex edge starts / is whole
EDGE_NOISE = 2.0  # x the samples' noise (standard deviation): how far the smoothing may move an edge inward
EDGE_BAND = 3.0  # voxels from the raw zero level where a 2^3 cell's corner looks for an edge (its voxels within ~2)


@wp.func
def tap(bmap: wp.array3d(dtype=wp.int32), f: wp.array(dtype=float), t: int, c: wp.vec3i, dx: int, dy: int, dz: int):
    """weight_at of voxel c + (dx, dy, dz), c being active voxel t: read directly when it lies in
    c's block (half the taps of an even voxel; the block map is looked up for the rest)."""
    if in_block(c, wp.vec3i(dx, dy, dz)):
        return f[t + (dx * BS + dy) * BS + dz]
    return weight_at(bmap, f, t, c[0] + dx, c[1] + dy, c[2] + dz)


@wp.func
def tangent_hessian(bmap: wp.array3d(dtype=wp.int32), f: wp.array(dtype=float), t: int, c: wp.vec3i):
    """(unit gradient direction of f at voxel t, the Hessian of f projected on the plane across it
    and divided by |grad f| (the curvature matrix of f's level set, 1/voxel), |grad f|), from taps
    2 voxels apart: they cancel the 2-voxel ripple that the weight blur's taps keep (a lattice of
    2 voxels' spacing leaves one, which 1-voxel differences read as edges on the lattice sphere)."""
    f0 = f[t]
    xp = tap(bmap, f, t, c, 2, 0, 0)
    xm = tap(bmap, f, t, c, -2, 0, 0)
    yp = tap(bmap, f, t, c, 0, 2, 0)
    ym = tap(bmap, f, t, c, 0, -2, 0)
    zp = tap(bmap, f, t, c, 0, 0, 2)
    zm = tap(bmap, f, t, c, 0, 0, -2)
    g = wp.vec3(xp - xm, yp - ym, zp - zm) / 4.0
    gl = wp.length(g)
    if gl < 1.0e-20:
        return wp.vec3(0.0), wp.mat33(0.0), 0.0
    hxy = (
        tap(bmap, f, t, c, 2, 2, 0)
        - tap(bmap, f, t, c, 2, -2, 0)
        - tap(bmap, f, t, c, -2, 2, 0)
        + tap(bmap, f, t, c, -2, -2, 0)
    ) / 16.0
    hxz = (
        tap(bmap, f, t, c, 2, 0, 2)
        - tap(bmap, f, t, c, 2, 0, -2)
        - tap(bmap, f, t, c, -2, 0, 2)
        + tap(bmap, f, t, c, -2, 0, -2)
    ) / 16.0
    hyz = (
        tap(bmap, f, t, c, 0, 2, 2)
        - tap(bmap, f, t, c, 0, 2, -2)
        - tap(bmap, f, t, c, 0, -2, 2)
        + tap(bmap, f, t, c, 0, -2, -2)
    ) / 16.0
    h = wp.mat33(
        0.25 * (xp - 2.0 * f0 + xm),
        hxy,
        hxz,
        hxy,
        0.25 * (yp - 2.0 * f0 + ym),
        hyz,
        hxz,
        hyz,
        0.25 * (zp - 2.0 * f0 + zm),
    )
    n = g / gl
    p = wp.identity(n=3, dtype=float) - wp.outer(n, n)
    return n, p * h * p / gl, gl


@wp.kernel
def edge_gate(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    wide: wp.array(dtype=float),
    offset: wp.array(dtype=wp.vec3),
    phi: wp.array(dtype=float),
    band: float,
    k0: float,
    k1: float,
    gate: wp.array(dtype=float),
    sample: wp.array(dtype=float),
    base: int,
):
    """Per cell of 2^3 voxels (thread u: its first voxel, the even one, in block u // 64; gate and
    sample hold 64 cells a block, voxels.gate_cell maps a voxel to its cell), where that
    voxel lies within `band` of the raw field's zero level (phi): gate = how much of an edge it
    is, 0 below the convex curvature k0 of the blurred weights' level set, 1 above k1 (1/voxel;
    smooth between); sample = |offset . e| (voxels), the centroid offset x - xbar along the edge
    direction e, where the level set bends one way only (an edge, not a corner), else -1.

    The weights grow into the body, so a convex level set has a negative curvature matrix here:
    its most negative eigenvalue is the edge's curvature, and e lies across the normal and that
    eigenvalue's direction. On a lattice the centroid never leaves the plane across the edge; on
    random samples it wanders along the edge as much as across, by the noise of the field.

    The blurred weights vary over their blur width (3-4 voxels), so one value per 2 voxels
    resolves the gate, at an eighth of the cost of one per voxel. A cell's gate sits at a fixed place in the world, so it changes smoothly in time as
    the particles move."""
    u = wp.tid() + base
    gate[u] = 0.0
    sample[u] = -1.0
    c = u % 64
    t = (u // 64) * BV + ((c // 16) * 2 * BS + ((c // 4) % 4) * 2) * BS + (c % 4) * 2
    if wp.abs(phi[t]) >= band:
        return
    n, m, gl = tangent_hessian(bmap, wide, t, voxel_of(t, bcoord))
    if gl == 0.0:
        return
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    m2 = m * m
    det = 0.5 * (tr * tr - (m2[0, 0] + m2[1, 1] + m2[2, 2]))  # the two tangent eigenvalues' product
    disc = wp.sqrt(wp.max(tr * tr - 4.0 * det, 0.0))
    lo = 0.5 * (tr - disc)
    hi = 0.5 * (tr + disc)
    s = wp.clamp((-lo - k0) / (k1 - k0), 0.0, 1.0)
    if s == 0.0:
        return
    gate[u] = s * s * (3.0 - 2.0 * s)
    if wp.abs(hi) > 0.5 * wp.abs(lo):
        return  # a corner or a blob: no one direction along the edge
    # (m - hi) m = lo (lo - hi) v v^T, v the edge's curvature direction (m n = 0 removes the normal)
    q = (m - hi * wp.identity(n=3, dtype=float)) * m
    v = wp.vec3(q[0, 0], q[1, 0], q[2, 0])
    for a in range(1, 3):
        col = wp.vec3(q[0, a], q[1, a], q[2, a])
        if wp.length_sq(col) > wp.length_sq(v):
            v = col
    e = wp.cross(n, v)
    el = wp.length(e)
    if el > 0.0:
        sample[u] = wp.abs(wp.dot(offset[t], e)) / el


@wp.kernel
def block_samples(sample: wp.array(dtype=float), sums: wp.array(dtype=wp.vec2), base: int):
    """sums[b] = (sum of block b's 64 samples >= 0, how many): a thread per block, so the sums
    need no atomics on the CPU's threads."""
    b = wp.tid() + base
    acc = wp.vec2(0.0)
    for l in range(64):
        s = sample[b * 64 + l]
        if s >= 0.0:
            acc += wp.vec2(s, 1.0)
    sums[b] = acc


@wp.kernel
def block_noise(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    sums: wp.array(dtype=wp.vec2),
    scale: float,
    noise: wp.array(dtype=float),
    base: int,
):
    """noise[b] = the samples' standard deviation over block b and its 26 neighbours (voxels;
    mean |offset . e| x sqrt(pi / 2), as for a normal distribution), or -1 where none holds a
    sample. 24^3 voxels hold a few dozen independent samples (the field's noise is correlated
    over the kernel radius, ~4 voxels), and the estimate changes smoothly from block to block."""
    b = wp.tid() + base
    c = bcoord[b] * BS
    acc = wp.vec2(0.0)
    for di in range(-1, 2):
        for dj in range(-1, 2):
            for dk in range(-1, 2):
                s = slot(bmap, c[0] + di * BS, c[1] + dj * BS, c[2] + dk * BS)
                if s >= 0:
                    acc += sums[s // BV]
    noise[b] = wp.where(acc[1] > 0.0, scale * 1.2533141 * acc[0] / wp.max(acc[1], 1.0), -1.0)


def edges(bcoord, bmap, wide, offset, phi, grid: SparseGrid) -> tuple:
    """(gate per 2^3-voxel cell, noise per active block, sample per cell) for the smoothing's
    inward limit: where the blurred weights' level set bends like an edge, and how noisy the
    samples are around each block (voxels). `wide`: the weights the normal came from, of blur
    width grid.wide_sigma voxels."""
    nact = bcoord.shape[0]
    gate, sample = wp.empty(nact * 64, dtype=float), wp.empty(nact * 64, dtype=float)  # a 2^3-voxel cell each
    k0, k1 = (c / grid.wide_sigma for c in EDGE_CURVATURE)
    split(wp, edge_gate, nact * 64, [bcoord, bmap, wide, offset, phi, EDGE_BAND, k0, k1, gate, sample])
    sums, noise = wp.empty(nact, dtype=wp.vec2), wp.empty(nact, dtype=float)
    split(wp, block_samples, nact, [sample, sums])
    split(wp, block_noise, nact, [bcoord, bmap, sums, EDGE_NOISE, noise])
    return gate, noise, sample  # sample < 0 where a gate is open: a corner or a blob (mpmfx.surface.sharpen)
