"""Binning pass: particles to grid coordinates, binned into blocks and gather cells.

Counts per block and per gather cell (CELLS_PER_BLOCK per block edge), the order that sorts the
particles by cell, and their grid positions in that order. GPU: Warp's radix sort; CPU: a
counting sort from the cell counts in one pass.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from mpmfx.surface.grid import SparseGrid
from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import scan, split
from mpmfx.surface.voxels import BS, CS

CELLS_PER_BLOCK = 2  # gather cells per block edge (CS = BS / 2 voxels)

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})

COUNT_NUDGE = wp.constant(0.01)  # voxels: float32 rounding of grid coordinates up to ~1e5 voxels (count_blocks)


@wp.kernel
def bounds(x: wp.array(dtype=wp.vec3), threads: int, out: wp.array(dtype=float)):
    """out[0:3] = min, out[3:6] = max of the finite positions, out[6] += count of non-finite
    ones; each thread reduces x[t], x[t + threads], ... (coalesced), then 7 atomics."""
    t = wp.tid()
    lo = wp.vec3(1.0e30)
    hi = wp.vec3(-1.0e30)
    bad = float(0.0)
    for p in range(t, x.shape[0], threads):
        q = x[p]
        if wp.isfinite(q[0]) and wp.isfinite(q[1]) and wp.isfinite(q[2]):
            lo = wp.min(lo, q)
            hi = wp.max(hi, q)
        else:
            bad += 1.0
    for a in range(3):
        wp.atomic_min(out, a, lo[a])
        wp.atomic_max(out, 3 + a, hi[a])
    if bad > 0.0:
        wp.atomic_add(out, 6, bad)


@wp.kernel
def to_grid(x: wp.array(dtype=wp.vec3), origin: wp.vec3, inv_voxel: float, g: wp.array(dtype=wp.vec3)):
    p = wp.tid()
    g[p] = (x[p] - origin) * inv_voxel


@wp.kernel
def count_blocks(
    g: wp.array(dtype=wp.vec3),
    counts: wp.array3d(dtype=wp.int32),
    cells: wp.array3d(dtype=wp.int32),
    keys: wp.array(dtype=wp.int32),
    order: wp.array(dtype=wp.int32),
):
    """Particles per block and per gather cell (CS^3 voxels); keys[p] = linear cell index of
    particle p, order[p] = p (to sort).

    The block counts judge how full a block is (classify_blocks), so a particle within
    COUNT_NUDGE voxels below a block face counts for the block above: a lattice plane lying on a
    block face (x = k h, as lattices laid from 0 do) would otherwise split between the blocks by
    float rounding, 3 and 5 layers instead of 4 and 4 (and many more blocks would be active)."""
    p = wp.tid()
    gp = g[p]
    ci = int(wp.floor(gp[0])) // CS
    cj = int(wp.floor(gp[1])) // CS
    ck = int(wp.floor(gp[2])) // CS
    bi = int(wp.floor(gp[0] + COUNT_NUDGE)) // BS
    bj = int(wp.floor(gp[1] + COUNT_NUDGE)) // BS
    bk = int(wp.floor(gp[2] + COUNT_NUDGE)) // BS
    # the grid's margin blocks hold no particle, so bi .. bk stay inside it
    wp.atomic_add(counts, bi, bj, bk, 1)
    wp.atomic_add(cells, ci, cj, ck, 1)
    keys[p] = (ci * cells.shape[1] + cj) * cells.shape[2] + ck
    order[p] = p


@wp.kernel
def sorted_copy(src: wp.array(dtype=wp.vec3), order: wp.array(dtype=wp.int32), dst: wp.array(dtype=wp.vec3), base: int):
    """dst[q] = src[order[q]]."""
    q = wp.tid() + base
    dst[q] = src[order[q]]


@wp.kernel
def sorted_velocity(
    src: wp.array(dtype=wp.vec3), order: wp.array(dtype=wp.int32), dst: wp.array(dtype=wp.vec3), base: int
):
    """dst[q] = src[order[q]], a non-finite velocity as 0 (one bad particle must not poison its
    neighbours' velocity; here it costs nothing, where a host pass over 10M costs 20-40 ms)."""
    q = wp.tid() + base
    u = src[order[q]]
    if not (wp.isfinite(u[0]) and wp.isfinite(u[1]) and wp.isfinite(u[2])):
        u = wp.vec3(0.0)
    dst[q] = u


@cpu_kernel
def counting_sort(
    keys: wp.array(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    cursor: wp.array(dtype=wp.int32),
    order: wp.array(dtype=wp.int32),
):
    """order = the particles sorted by cell key, ties in particle order: what
    wp.utils.radix_sort_pairs (a stable sort) gives for (keys, order = 0 .. n - 1), from the
    cells' first slots `starts` (the exclusive scan of their counts). keys: (n,) cell key of
    each particle (count_blocks); cursor: (cells,) zeros, the particles placed per cell so far.
    One thread (launch dim 1) walks the particles in order: on one CPU core that is one pass
    over them where the radix sort makes four over keys and values."""
    n = keys.shape[0]
    p = int(0)
    while p < n:  # not range(): a run-time bound costs a step-sign test per iteration
        k = keys[p]
        s = cursor[k]
        order[starts[k] + s] = p
        cursor[k] = s + 1
        p += 1


def particle_bounds(x) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (3,) float64 world bounds of x (wp.array of vec3), computed on the device;
    ValueError when a position is NaN or infinite."""
    out = wp.array(np.array([np.inf] * 3 + [-np.inf] * 3 + [0.0], np.float32), dtype=float)
    threads = min(x.shape[0], 1 << 16)  # each thread reduces a strided slice, then 7 atomics
    wp.launch(bounds, threads, inputs=[x, threads, out])
    b = out.numpy().astype(np.float64)
    if b[6] > 0:
        raise ValueError(f"surface_particles: x holds {int(b[6])} NaN or inf positions; fix the simulation frame")
    return b[:3], b[3:6]


def grid_positions(x, grid: SparseGrid):
    """x (wp.array of vec3, m) in grid coordinates (voxels from grid.origin): float32 keeps
    1e-4 voxel at 2000 voxels across."""
    g = wp.empty(x.shape[0], dtype=wp.vec3)
    wp.launch(to_grid, x.shape[0], inputs=[x, wp.vec3(*grid.origin.astype(np.float32)), 1.0 / grid.voxel, g])
    return g


def _count(g, grid: SparseGrid, sort_slots: int):
    n = g.shape[0]
    counts = wp.zeros(grid.nblocks, dtype=wp.int32)
    cells = wp.zeros(tuple(b * CELLS_PER_BLOCK for b in grid.nblocks), dtype=wp.int32)
    keys = wp.empty(sort_slots, dtype=wp.int32)
    order = wp.empty(sort_slots, dtype=wp.int32)
    wp.launch(count_blocks, n, inputs=[g, counts, cells, keys, order])
    starts = scan(wp, cells.flatten(), inclusive=False)
    return counts, cells, starts, keys, order


def bin_particles_by_voxel(g, grid: SparseGrid):
    """(counts per block (3-D int32), counts per gather cell (3-D, CELLS_PER_BLOCK per block and
    axis), first sorted slot per cell (flat), particle order sorted by cell): Warp's radix sort."""
    n = g.shape[0]
    counts, cells, starts, keys, order = _count(g, grid, 2 * n)  # radix_sort_pairs sorts through a second half
    wp.utils.radix_sort_pairs(keys, order, n)
    return counts, cells, starts, order


def bin_particles_by_block(g, grid: SparseGrid):
    """bin_particles_by_voxel' result, the radix sort's order from the cell counts in one pass (counting_sort)."""
    counts, cells, starts, keys, order = _count(g, grid, g.shape[0])
    wp.launch(counting_sort, 1, inputs=[keys, starts, wp.zeros(starts.shape[0], dtype=wp.int32), order])
    return counts, cells, starts, order


def sorted_positions(g, order):
    """g in the gather cells' order (gs[q] = g[order[q]], (n,) vec3).

    The kernels that read a cell's particles (the gathers) then read consecutive memory instead
    of following `order`, and those that take one particle at a time in any order
    (mark_near_blocks, count_component_particles) touch the block map, the voxel arrays and the
    counters in space order: in the caller's order random samples (what simulated particles look
    like) jump from one block to the next, where a lattice's neighbours follow each other.
    Their results do not depend on the order."""
    gs = wp.empty(g.shape[0], dtype=wp.vec3)
    split(wp, sorted_copy, g.shape[0], [g, order, gs])
    return gs
