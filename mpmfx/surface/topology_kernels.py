"""Warp kernels of the sparse surfacer's topology pass: flood fills that find bubbles (outside
voxels the boundary does not reach) and specks (inside voxels no particle holds), and the
removal of small inside components (`SurfaceParams.min_feature_particles`).

Block layout and accessors as in :mod:`mpmfx.surface.sparse_kernels`. The sweeps work in place
along block lines and are repeated until nothing changes, so any interleaving of their threads
(GPU, or CPU chunks on several threads: mpmfx.surface.launch) settles to the same result.
"""

import warp as wp

from mpmfx.surface.sparse_kernels import (BS, BV, LABEL_NONE, TILE_INSIDE, TILE_OUTSIDE, in_block, interior, line_start, line_voxel,
                                          slot, voxel_of)


@wp.kernel
def mark_particle_voxels(g: wp.array(dtype=wp.vec3), bmap: wp.array3d(dtype=wp.int32), mark: wp.array(dtype=wp.int32),
                         base: int):
    """mark = 1 at the voxel nearest to each particle (seeds of genuine inside components)."""
    p = wp.tid() + base
    gp = g[p]
    s = slot(bmap, int(wp.round(gp[0])), int(wp.round(gp[1])), int(wp.round(gp[2])))
    if s >= 0:
        mark[s] = 1


@wp.kernel
def seed_reached(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    mark: wp.array(dtype=wp.int32),
    seed_depth: float,
    specks: int,
    reached: wp.array(dtype=wp.int32),
    pending: wp.array(dtype=wp.int32),
    base: int,
):
    """Seeds of a flood fill looking for bubbles (specks == 0: every inside voxel is a seed, and
    outside voxels touching an OUTSIDE tile) or for specks (specks == 1: every outside voxel,
    inside voxels touching an INSIDE tile, and particle voxels at least `seed_depth` deep: a lone
    particle is ~r deep at its centre, a voxel that sampling noise flips is barely below zero).
    pending[b] = 1 for blocks holding an unreached voxel."""
    t = wp.tid() + base
    c = voxel_of(t, bcoord)
    out = phi[t] > 0.0
    r = int(0)
    if specks == 0 and not out:
        r = 1
    if specks != 0 and (out or (mark[t] != 0 and phi[t] <= -seed_depth)):
        r = 1
    if r == 0 and not interior(c):  # an interior voxel has no tile neighbour
        for n in range(6):
            o = wp.vec3i(0)
            o[n // 2] = 2 * (n % 2) - 1
            s = int(0)
            if not in_block(c, o):
                s = slot(bmap, c[0] + o[0], c[1] + o[1], c[2] + o[2])
            if (out and s == TILE_OUTSIDE) or ((not out) and s == TILE_INSIDE):
                r = 1
    reached[t] = r
    if r == 0:
        pending[t // BV] = 1  # (zeroed before) the sweeps skip blocks with nothing left to reach


@wp.kernel
def sweep_reached(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    reached: wp.array(dtype=wp.int32),
    active: wp.array(dtype=wp.int32),
    axis: int,
    changed: wp.array(dtype=wp.int32),
    moved: wp.array(dtype=wp.int32),
    base: int,
):
    """Flood fill through same-sign voxels along one block line, forward then backward,
    starting from the neighbouring block's voxel: 8 voxels of progress per launch. Only
    blocks with active[b] != 0 (see active_blocks) are swept; moved[b] = 1 where a voxel of
    block b was reached (the next round's activity)."""
    tid = wp.tid() + base
    b = tid // 64
    if active[b] == 0:
        return
    l = tid - b * 64
    corner = bcoord[b] * BS
    first, st = line_start(axis, l)
    count = int(0)
    for dirn in range(2):
        start = line_voxel(axis, wp.where(dirn == 0, -1, BS), l) + corner
        sl = slot(bmap, start[0], start[1], start[2])
        carry_r = int(0)
        carry_out = False
        if sl >= 0:
            carry_r = reached[sl]
            carry_out = phi[sl] > 0.0
        for q in range(BS):
            t = b * BV + first + wp.where(dirn == 0, q, BS - 1 - q) * st
            out = phi[t] > 0.0
            r = reached[t]
            if r == 0 and carry_r != 0 and carry_out == out:
                reached[t] = 1
                r = 1
                count += 1
            carry_r = r
            carry_out = out
    if count > 0:
        changed[0] = 1  # a flag: every writer stores the same value, no atomic contention
        moved[b] = 1


@wp.kernel
def active_blocks(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    pending: wp.array(dtype=wp.int32),
    moved: wp.array(dtype=wp.int32),
    first: int,
    active: wp.array(dtype=wp.int32),
):
    """active[b] = 1 for the blocks a flood round must sweep: those holding an unreached voxel
    after seeding (pending) and, after the first round (first == 0), where the block or a face
    neighbour reached a voxel in the previous round (moved). A voxel reached in round k can
    only reach others through blocks swept in round k + 1, and a line sweep carries reach along
    its whole line from either end, so the fill still ends closed, as if every block were swept.
    The component labels' rounds (sparse._remove_small) are taken the same way: a block whose
    labels and face neighbours' did not move sweeps to the labels it holds."""
    b = wp.tid()
    a = pending[b]
    if a != 0 and first == 0:
        m = moved[b]
        c = bcoord[b] * BS
        for n in range(6):
            o = wp.vec3i(0)
            o[n // 2] = (2 * (n % 2) - 1) * BS
            s = slot(bmap, c[0] + o[0], c[1] + o[1], c[2] + o[2])
            if s >= 0:
                m += moved[s // BV]
        if m == 0:
            a = 0
    active[b] = a


@wp.kernel
def flip_unreached(phi: wp.array(dtype=float), reached: wp.array(dtype=wp.int32), inside_value: float, outside_value: float):
    """Outside voxels the boundary does not reach are bubbles (-> inside); inside voxels no
    particle reaches are specks of a noisy field (-> outside)."""
    t = wp.tid()
    if reached[t] == 0:
        if phi[t] > 0.0:
            phi[t] = inside_value
        else:
            phi[t] = outside_value


@wp.kernel
def init_inside_labels(
    bcoord: wp.array(dtype=wp.vec3i), bmap: wp.array3d(dtype=wp.int32), phi: wp.array(dtype=float), labels: wp.array(dtype=wp.int32),
    base: int,
):
    """Inside voxels: own label t + 1, or 0 when touching an INSIDE tile (a big body); else -1."""
    t = wp.tid() + base
    lab = LABEL_NONE
    if phi[t] <= 0.0:
        lab = t + 1
        c = voxel_of(t, bcoord)
        for n in range(6):
            o = wp.vec3i(0)
            o[n // 2] = 2 * (n % 2) - 1
            if slot(bmap, c[0] + o[0], c[1] + o[1], c[2] + o[2]) == TILE_INSIDE:
                lab = 0
    labels[t] = lab


@wp.func
def sweep_min_line(bcoord: wp.array(dtype=wp.vec3i), bmap: wp.array3d(dtype=wp.int32), labels: wp.array(dtype=wp.int32),
                   axis: int, b: int, l: int):
    """Carry the smallest label through labelled voxels along line l of block b, both ways;
    returns how many labels it lowered."""
    corner = bcoord[b] * BS
    first, st = line_start(axis, l)
    count = int(0)
    for dirn in range(2):
        start = line_voxel(axis, wp.where(dirn == 0, -1, BS), l) + corner
        sl = slot(bmap, start[0], start[1], start[2])
        carry = LABEL_NONE
        if sl >= 0:
            carry = labels[sl]
        for q in range(BS):
            t = b * BV + first + wp.where(dirn == 0, q, BS - 1 - q) * st
            lab = labels[t]
            if lab >= 0 and carry >= 0 and carry < lab:
                labels[t] = carry
                lab = carry
                count += 1
            carry = lab
    return count


@wp.kernel
def sweep_min_labels(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    labels: wp.array(dtype=wp.int32),
    active: wp.array(dtype=wp.int32),
    axis: int,
    changed: wp.array(dtype=wp.int32),
    moved: wp.array(dtype=wp.int32),
    base: int,
):
    """Carry the smallest label through labelled voxels along one block line, both ways
    (blocks with active[b] != 0); moved[b] = 1 where a label of block b was lowered."""
    tid = wp.tid() + base
    b = tid // 64
    if active[b] == 0:
        return
    count = sweep_min_line(bcoord, bmap, labels, axis, b, tid - b * 64)
    if count > 0:
        changed[0] = 1  # flags: every writer stores the same value, no atomic contention
        moved[b] = 1


@wp.kernel
def count_component_particles(
    g: wp.array(dtype=wp.vec3), bmap: wp.array3d(dtype=wp.int32), labels: wp.array(dtype=wp.int32), counts: wp.array(dtype=wp.int32)
):
    p = wp.tid()
    gp = g[p]
    s = slot(bmap, int(wp.round(gp[0])), int(wp.round(gp[1])), int(wp.round(gp[2])))
    if s >= 0:
        lab = labels[s]
        if lab > 0:
            wp.atomic_add(counts, lab, 1)


@wp.kernel
def remove_small_components(
    labels: wp.array(dtype=wp.int32), counts: wp.array(dtype=wp.int32), min_count: int, outside_value: float, phi: wp.array(dtype=float),
    base: int,
):
    t = wp.tid() + base
    lab = labels[t]
    if lab > 0 and counts[lab] < min_count:
        phi[t] = outside_value
