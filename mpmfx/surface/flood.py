"""Topology pass: the flood fills. Outside voxels not connected to an OUTSIDE block
are bubbles (-> inside); inside voxels not connected to a particle or an INSIDE block are
specks of the noisy field (-> outside).

GPU: sweeps along block lines (seed_reached, sweep_reached, flip_unreached), in place and
repeated until nothing changes, so any interleaving of their threads settles to the same result.
CPU: the same fill on bit words (:mod:`mpmfx.surface.bitwords`), a block per thread filled to
its fixpoint each round. The fill is the same closed set as the line sweeps' (the seeds'
components among same-sign active voxels, 6-connected), so the flipped voxels are the same;
only the round count (a statistic) differs. Threads on several CPU cores read a neighbour's
words while it may be writing them: reach only grows, a stale read is made up in the next
round, and a round in which no block changed read only final words.
"""

from __future__ import annotations

import logging

import warp as wp

from mpmfx.surface.bitwords import ALL, BYTE, by_tile, face_mask, large_piece, spread, take_face, tile_face, vec8u
from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import launch_blocks, launch_split, split
from mpmfx.surface.lines import rows, side_code, vec8
from mpmfx.surface.voxels import (
    BS,
    BV,
    TILE_INSIDE,
    TILE_OUTSIDE,
    in_block,
    interior,
    line_start,
    line_voxel,
    slot,
    voxel_of,
)

log = logging.getLogger(__name__)

MAX_SWEEP_ROUNDS = 1024
SEEDS = {"bubbles": 0, "specks": 1, "bodies": 2}  # seed_bits' modes

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


# the bit-word flood's two kernels (fill_bits: both devices run them) in a Warp module each: the
# flood's compile, the surfacer's longest once sharpen was split, runs on three threads
SEED_MODULE, SWEEP_MODULE = __name__ + "_seed", __name__ + "_sweep"


@wp.kernel
def mark_particle_voxels(
    g: wp.array(dtype=wp.vec3), bmap: wp.array3d(dtype=wp.int32), mark: wp.array(dtype=wp.int32), base: int
):
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
    The component labels' rounds (components.remove_small) are taken the same way: a block whose
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
def flip_unreached(
    phi: wp.array(dtype=float), reached: wp.array(dtype=wp.int32), inside_value: float, outside_value: float
):
    """Outside voxels the boundary does not reach are bubbles (-> inside); inside voxels no
    particle reaches are specks of a noisy field (-> outside)."""
    t = wp.tid()
    if reached[t] == 0:
        if phi[t] > 0.0:
            phi[t] = inside_value
        else:
            phi[t] = outside_value


@wp.kernel(enable_backward=False, module=SEED_MODULE)
def seed_bits(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi8: wp.array(dtype=vec8),
    mark: wp.array(dtype=wp.uint64),
    seed_depth: float,
    seeds: int,
    min_count: int,
    sign: wp.array(dtype=wp.uint64),
    reached: wp.array(dtype=wp.uint64),
    pending: wp.array(dtype=wp.int32),
    base: int,
):
    """seed_reached for one block, as bit words (seeds 0: bubbles, 1:
    specks, as its `specks`; 2: bodies, every outside voxel, the inside ones next to an
    INSIDE tile, and with min_count > 0 a block's inside voxels where they are one piece
    within the block that holds at least min_count particles' voxels: see small_labels);
    pending[b] = 1 where a voxel is left to reach. phi8: the level set as vec8 rows along z
    (lines.rows); mark: the particles' voxels as bit words (mark_particle_bits; read by
    the specks' and the bodies' seeds)."""
    b = wp.tid() + base
    bc = bcoord[b]
    left = int(0)
    sv = vec8u(wp.uint64(0))
    rv = vec8u(wp.uint64(0))
    xm = side_code(bmap, bc, 0, -1)
    xp = side_code(bmap, bc, 0, 1)
    ym = side_code(bmap, bc, 1, -1)
    yp = side_code(bmap, bc, 1, 1)
    zm = side_code(bmap, bc, 2, -1)
    zp = side_code(bmap, bc, 2, 1)
    for x in range(BS):
        s = wp.uint64(0)
        r = wp.uint64(0)
        # a row of 8 voxels along z (bits y * 8 + z) at a time, its bits selected without a
        # branch per voxel: the sign flips where the surface is, so those branches would
        # mispredict
        marks = wp.uint64(0)
        if seeds == 1:  # seeds is the launch's: this branch always goes the same way
            marks = mark[b * BS + x]
        for y in range(BS):
            row = phi8[(b * BS + x) * BS + y]
            sb = int(0)
            rb = int(0)
            for z in range(BS):
                sb = sb | wp.where(row[z] > 0.0, 1 << z, 0)
                if seeds == 1:
                    rb = rb | wp.where(row[z] <= -seed_depth, 1 << z, 0)
            if seeds == 1:  # outside, or a particle's voxel at least seed_depth deep
                rb = sb | (rb & int((marks >> wp.uint64(y * BS)) & BYTE))
            if seeds == 0:
                rb = (~sb) & 255
            if seeds == 2:
                rb = sb
            s = s | (wp.uint64(sb) << wp.uint64(y * BS))
            r = r | (wp.uint64(rb) << wp.uint64(y * BS))
        # an outside voxel next to an OUTSIDE tile, an inside one next to an INSIDE tile
        face = wp.uint64(0)
        if (x == 0 and xm < 0) or (x == BS - 1 and xp < 0):
            face = ALL
        face = face | tile_face(ym, 1, 0) | tile_face(yp, 1, 1) | tile_face(zm, 2, 0) | tile_face(zp, 2, 1)
        if face != wp.uint64(0):
            out_face = wp.uint64(0)
            inside_face = wp.uint64(0)
            if x == 0:
                out_face, inside_face = by_tile(xm, ALL, out_face, inside_face)
            if x == BS - 1:
                out_face, inside_face = by_tile(xp, ALL, out_face, inside_face)
            out_face, inside_face = by_tile(ym, face_mask(1, 0), out_face, inside_face)
            out_face, inside_face = by_tile(yp, face_mask(1, 1), out_face, inside_face)
            out_face, inside_face = by_tile(zm, face_mask(2, 0), out_face, inside_face)
            out_face, inside_face = by_tile(zp, face_mask(2, 1), out_face, inside_face)
            r = r | (out_face & s) | (inside_face & (~s))
        sv[x] = s
        rv[x] = r
    if seeds == 2 and min_count > 0:
        marked = int(0)
        for x in range(BS):
            marked += wp.bit_count(mark[b * BS + x] & (~sv[x]))
        if large_piece(sv, marked, min_count):
            for x in range(BS):
                rv[x] = rv[x] | (~sv[x])
    for x in range(BS):
        sign[b * BS + x] = sv[x]
        reached[b * BS + x] = rv[x]
        if rv[x] != ALL:
            left = 1
    pending[b] = left


@cpu_kernel
def mark_particle_bits(
    bcoord: wp.array(dtype=wp.vec3i),
    cells: wp.array3d(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    gs: wp.array(dtype=wp.vec3),
    mark: wp.array(dtype=wp.uint64),
    base: int,
):
    """mark_particle_voxels for active block b (thread = block) as its 8 bit
    words (seed_bits' layout): bit set at the voxel nearest to a particle (wp.round of its grid
    coordinates, as there). A particle whose nearest voxel lies in b lies within half a voxel
    below b's span or in it, so in the gather cells 2 bc - 1 .. 2 bc + 1 along each axis
    (sparse.CELLS_PER_BLOCK = 2); gs: the positions in the cells' order (starts: each cell's
    first slot), so a column of those cells is one run of slots. Only this thread writes
    block b's words: the launch splits across CPU threads. The int32 marks cost 4 bytes a
    voxel to clear, write and read in the specks' seeds (8 MB at 100k random torus "fine")."""
    b = wp.tid() + base
    bc = bcoord[b]
    c = bc * BS
    lo = wp.vec3i(0)
    hi = wp.vec3i(0)
    for a in range(3):
        lo[a] = wp.max(2 * bc[a] - 1, 0)
        hi[a] = wp.min(2 * bc[a] + 1, cells.shape[a] - 1)
    words = vec8u(wp.uint64(0))
    for ci in range(lo[0], hi[0] + 1):
        for cj in range(lo[1], hi[1] + 1):
            lin = (ci * cells.shape[1] + cj) * cells.shape[2]
            q = starts[lin + lo[2]]
            end = starts[lin + hi[2]] + cells[ci, cj, hi[2]]
            while q < end:  # not range(): a run-time bound costs a step-sign test per iteration
                gp = gs[q]
                i = int(wp.round(gp[0])) - c[0]
                j = int(wp.round(gp[1])) - c[1]
                k = int(wp.round(gp[2])) - c[2]
                if i >= 0 and i < BS and j >= 0 and j < BS and k >= 0 and k < BS:
                    words[i] = words[i] | (wp.uint64(1) << wp.uint64(j * BS + k))
                q += 1
    for x in range(BS):
        mark[b * BS + x] = words[x]


@wp.kernel(enable_backward=False, module=SWEEP_MODULE)
def flood_bits(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    sign: wp.array(dtype=wp.uint64),
    reached: wp.array(dtype=wp.uint64),
    active: wp.array(dtype=wp.int32),
    changed: wp.array(dtype=wp.int32),
    moved: wp.array(dtype=wp.int32),
    base: int,
):
    """One round for block b (if active[b]): take in the reached face voxels of the 6
    neighbour blocks (active ones; tiles pass nothing, as in sweep_reached), spread to the
    fixpoint inside the block; moved[b] = 1 and changed += 1 where a voxel was reached."""
    b = wp.tid() + base
    if active[b] == 0:
        return
    bc = bcoord[b]
    s = vec8u(wp.uint64(0))
    r = vec8u(wp.uint64(0))
    for x in range(BS):
        s[x] = sign[b * BS + x]
        r[x] = reached[b * BS + x]
    n = side_code(bmap, bc, 0, -1)
    if n >= 0:
        r[0] = take_face(r[0], s[0], reached[n * BS + BS - 1], sign[n * BS + BS - 1], ALL)
    n = side_code(bmap, bc, 0, 1)
    if n >= 0:
        r[BS - 1] = take_face(r[BS - 1], s[BS - 1], reached[n * BS], sign[n * BS], ALL)
    for axis in range(1, 3):
        for side in range(2):
            n = side_code(bmap, bc, axis, 2 * side - 1)
            if n >= 0:
                # the neighbour's opposite face moved onto this block's face
                sh = wp.uint64(wp.where(axis == 1, 56, 7))
                for x in range(BS):
                    nr = reached[n * BS + x]
                    ns = sign[n * BS + x]
                    if side == 0:
                        nr = nr >> sh
                        ns = ns >> sh
                    else:
                        nr = nr << sh
                        ns = ns << sh
                    r[x] = take_face(r[x], s[x], nr, ns, face_mask(axis, side))
    r = spread(s, r)
    any_new = int(0)
    for x in range(BS):
        if r[x] != reached[b * BS + x]:  # only this thread writes block b's words
            reached[b * BS + x] = r[x]
            any_new = 1
    if any_new != 0:
        moved[b] = 1
        wp.atomic_add(changed, 0, 1)


@cpu_kernel
def flip_unreached_bits(
    reached: wp.array(dtype=wp.uint64), inside_value: float, outside_value: float, phi: wp.array(dtype=float), base: int
):
    """flip_unreached for the 64 voxels of word w (thread = block * 8 + x)."""
    w = wp.tid() + base
    r = reached[w]
    if r == ALL:
        return
    for q in range(BS * BS):
        if ((r >> wp.uint64(q)) & wp.uint64(1)) == wp.uint64(0):
            t = w * BS * BS + q
            if phi[t] > 0.0:
                phi[t] = inside_value
            else:
                phi[t] = outside_value


def active_rounds(bcoord, bmap, pending, sweep) -> tuple[int, bool]:
    """(rounds, settled): rounds of sweep(active, changed, moved) until one changes nothing, at
    most MAX_SWEEP_ROUNDS. The first sweeps the `pending` blocks (int32 flags), each later one
    only those where the previous round moved something, or next to one (active_blocks: a
    block whose own values and face neighbours' did not move would sweep to what it holds).
    sweep sets changed[0] and moved[b] where it changes block b."""
    nact = bcoord.shape[0]
    changed = wp.zeros(1, dtype=wp.int32)
    active, moved, was = wp.empty(nact, dtype=wp.int32), wp.zeros(nact, dtype=wp.int32), wp.zeros(nact, dtype=wp.int32)
    for rounds in range(1, MAX_SWEEP_ROUNDS + 1):
        wp.launch(active_blocks, nact, inputs=[bcoord, bmap, pending, was, int(rounds == 1), active])
        changed.zero_()
        moved.zero_()
        sweep(active, changed, moved)
        moved, was = was, moved
        if int(changed.numpy()[0]) == 0:
            return rounds, True
    return MAX_SWEEP_ROUNDS, False


def mark_particles_by_voxel(bcoord, bmap, cells, starts, gs):
    """The voxels nearest to a particle (the specks' seeds), an int32 each. gs: the grid positions."""
    mark = wp.zeros(max(bcoord.shape[0] * BS**3, 1), dtype=wp.int32)
    split(wp, mark_particle_voxels, gs.shape[0], [gs, bmap, mark])  # writes 1s: any interleaving agrees
    return mark


def mark_particles_by_block(bcoord, bmap, cells, starts, gs):
    """mark_particles_by_voxel' voxels as a bit each, in 8 words a block (what the bit fills read);
    gs in the gather cells' order (mpmfx.surface.binning.sorted_positions)."""
    mark = wp.empty(max(bcoord.shape[0] * BS, 1), dtype=wp.uint64)
    launch_blocks(wp, mark_particle_bits, [bcoord, cells, starts, gs, mark])
    return mark


def fix_topology(flood, bcoord, bmap, phi, mark, tiles, *, seed_depth: float) -> int:
    """Fill bubbles (outside voxels the boundary does not reach), then turn inside specks that
    hold no particle at least seed_depth deep to outside; returns the sweep rounds used.
    flood: a variant's flood_*. Bubbles first: a speck inside a bubble is then part of the body,
    and a speck turned outside joins an outside region the boundary reaches, so neither step
    undoes the other."""
    if phi.shape[0] == 0:
        return 0
    rounds = flood(bcoord, bmap, phi, mark, tiles, seed_depth, specks=False)
    rounds += flood(bcoord, bmap, phi, mark, tiles, seed_depth, specks=True)
    return rounds


def flood_by_voxel(bcoord, bmap, phi, mark, tiles, seed_depth: float, *, specks: bool) -> int:
    """One fill (bubbles, or specks), line sweeps a voxel line per thread; the sweep rounds used."""
    nvox = phi.shape[0]
    reached = wp.empty(nvox, dtype=wp.int32)
    pending = wp.zeros(bcoord.shape[0], dtype=wp.int32)
    split(wp, seed_reached, nvox, [bcoord, bmap, phi, mark, seed_depth, int(specks), reached, pending])

    def sweep(active, changed, moved):
        for axis in range(3):
            split(wp, sweep_reached, bcoord.shape[0] * 64, [bcoord, bmap, phi, reached, active, axis, changed, moved])

    rounds, settled = active_rounds(bcoord, bmap, pending, sweep)  # all pending blocks first, then near what moved
    if not settled:
        log.warning("topology flood fill did not settle in %d rounds; some bubbles may remain", MAX_SWEEP_ROUNDS)
    # unreached outside voxels are bubbles (-> inside), unreached inside ones specks (-> outside)
    wp.launch(flip_unreached, nvox, inputs=[phi, reached, tiles[1], tiles[0]])
    return rounds


def flood_by_block(bcoord, bmap, phi, mark, tiles, seed_depth: float, *, specks: bool) -> int:
    """flood_by_voxel on bit words, a block per thread filled to its fixpoint each round."""
    _, reached, rounds = fill_bits(bcoord, bmap, phi, mark, seed_depth, "specks" if specks else "bubbles")
    # flip_unreached from the bit words: unreached outside voxels -> tiles[1] (inside), unreached inside ones -> tiles[0]
    launch_split(
        wp, flip_unreached_bits, reached.shape[0], [reached, tiles[1], tiles[0], phi], device=phi.device, light=BS
    )  # a word per block line
    return rounds


def fill_bits(bcoord, bmap, phi, mark, seed_depth: float, seeds: str, min_count: int = 0):
    """(sign, reached, rounds): bit words of a block each (8 per block) after filling from
    the `seeds` (SEEDS) through same-sign active voxels, a block per thread per round, over
    the blocks near those that changed in the previous round (active_blocks)."""
    nact = bcoord.shape[0]
    sign, reached = wp.empty(nact * BS, dtype=wp.uint64), wp.empty(nact * BS, dtype=wp.uint64)
    pending = wp.empty(nact, dtype=wp.int32)
    blocks = {"device": phi.device, "min_split": 1}  # a block per thread: few threads, much work each
    launch_split(
        wp,
        seed_bits,
        nact,
        [bcoord, bmap, rows(phi), mark, seed_depth, SEEDS[seeds], min_count, sign, reached, pending],
        **blocks,
    )

    def sweep(active, changed, moved):  # a round visits only the blocks near the last round's changes: light
        launch_split(wp, flood_bits, nact, [bcoord, bmap, sign, reached, active, changed, moved], **blocks, light=1)

    rounds, settled = active_rounds(bcoord, bmap, pending, sweep)
    if not settled:
        log.warning("topology flood fill did not settle in %d rounds; some bubbles may remain", MAX_SWEEP_ROUNDS)
    return sign, reached, rounds
