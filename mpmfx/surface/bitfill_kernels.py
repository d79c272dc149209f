"""The topology flood fill on bit masks, a block per thread: the CPU path of
:mod:`mpmfx.surface.topology_kernels` (seed_reached, sweep_reached, flip_unreached).

A block's 512 voxels are 8 words of 64 bits, word x (the local x index) holding bit y * 8 + z:
`sign` (phi > 0) and `reached`. A thread takes one block, lets its reached voxels spread to
6-neighbours of the same sign inside the block until nothing changes (a few dozen word
operations per step instead of a voxel at a time), after first taking in the reached voxels
of the face neighbours in active blocks. Rounds repeat over the blocks near those that
changed until none does. The fill is the same closed set as the line sweeps' (the seeds'
components among same-sign active voxels, 6-connected), so the flipped voxels are the same;
only the round count (a statistic) differs. Threads on several CPU cores read a neighbour's
words while it may be writing them: reach only grows, a stale read is made up in the next
round, and a round in which no block changed read only final words.
"""

import warp as wp

from mpmfx.surface.line_kernels import side_code, vec8
from mpmfx.surface.sparse_kernels import BS, BV, LABEL_NONE, TILE_INSIDE, TILE_OUTSIDE
from mpmfx.surface.topology_kernels import sweep_min_line

vec8u = wp.types.vector(length=8, dtype=wp.uint64)
ALL = wp.constant(wp.uint64(0xFFFFFFFFFFFFFFFF))
Z_LOW = wp.constant(wp.uint64(0x7F7F7F7F7F7F7F7F))  # bit z of each y group, z = 0..6 (z + 1 in the group)
Z_FIRST = wp.constant(wp.uint64(0x0101010101010101))  # z = 0 of each y group
Y_LOW = wp.constant(wp.uint64(0x00FFFFFFFFFFFFFF))  # y groups 0..6
BYTE = wp.constant(wp.uint64(0xFF))


@wp.func
def bit(q: int):
    return wp.uint64(1) << wp.uint64(q)


@wp.func
def face_mask(axis: int, side: int):
    """Bits of a word on the block face `axis` (1: y, 2: z) at side 0 (low) or 1 (high)."""
    m = wp.uint64(0)
    if axis == 1:
        m = BYTE << wp.uint64(56 * side)
    else:
        m = Z_FIRST << wp.uint64(7 * side)
    return m


@wp.func
def tile_face(code: int, axis: int, side: int):
    """face_mask(axis, side) where `code` is a tile, else 0."""
    m = wp.uint64(0)
    if code < 0:
        m = face_mask(axis, side)
    return m


@wp.func
def by_tile(code: int, face: wp.uint64, out_face: wp.uint64, inside_face: wp.uint64):
    """(out_face, inside_face) with `face` added to the one of tile `code` (none if active)."""
    if code == TILE_OUTSIDE:
        return out_face | face, inside_face
    if code == TILE_INSIDE:
        return out_face, inside_face | face
    return out_face, inside_face


@wp.func
def spread(s: vec8u, r: vec8u):
    """r grown to its fixpoint inside one block: each set bit spreads to the 6-neighbours of
    the same sign (s) within the block's 8 words."""
    grow = int(1)
    while grow != 0:
        grow = int(0)
        for x in range(BS):  # along z and y inside each word
            ez = (~(s[x] ^ (s[x] >> wp.uint64(1)))) & Z_LOW  # bit q: voxels q and q + 1 (z) share a sign
            ey = (~(s[x] ^ (s[x] >> wp.uint64(8)))) & Y_LOW  # voxels q and q + 8 (y)
            w = r[x]
            more = int(1)
            while more != 0:
                v = w | ((w & ez) << wp.uint64(1)) | ((w >> wp.uint64(1)) & ez) | ((w & ey) << wp.uint64(8)) | (
                    (w >> wp.uint64(8)) & ey)
                more = wp.where(v != w, 1, 0)
                w = v
            r[x] = w
        for x in range(BS - 1):  # along x, up then down
            ex = ~(s[x] ^ s[x + 1])
            v = r[x + 1] | (r[x] & ex)
            if v != r[x + 1]:
                r[x + 1] = v
                grow = int(1)
        for k in range(BS - 1):
            x = BS - 2 - k
            ex = ~(s[x] ^ s[x + 1])
            v = r[x] | (r[x + 1] & ex)
            if v != r[x]:
                r[x] = v
                grow = int(1)
    return r


@wp.func
def large_piece(s: vec8u, marked: int, min_count: int):
    """Whether a block's inside voxels (the bits clear in its sign words s) are one piece within
    the block (6-connected) holding at least min_count particles' voxels (marked of them): its
    component then holds at least min_count particles (count_component_particles counts a
    particle at its nearest voxel, as the marks are set), so it is not small."""
    if marked < min_count:
        return False
    x0 = int(0)
    while x0 < BS - 1 and s[x0] == ALL:
        x0 += 1
    inside = ~s[x0]
    first = vec8u(wp.uint64(0))
    first[x0] = inside & (~inside + wp.uint64(1))  # the block's first inside voxel
    r = spread(s, first)
    for x in range(BS):
        if r[x] != ~s[x]:
            return False
    return True


@wp.kernel
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
    """topology_kernels.seed_reached for one block, as bit words (seeds 0: bubbles, 1:
    specks, as its `specks`; 2: bodies, every outside voxel, the inside ones next to an
    INSIDE tile, and with min_count > 0 a block's inside voxels where they are one piece
    within the block that holds at least min_count particles' voxels: see small_labels);
    pending[b] = 1 where a voxel is left to reach. phi8: the level set as vec8 rows along z
    (line_kernels.rows); mark: the particles' voxels as bit words (mark_particle_bits; read by
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
        # branch per voxel: the sign flips where the surface is, so those branches
        # mispredicted (4 launches, one thread, 100k "fine": lattice torus 29 -> 11 ms, sphere 21 -> 16)
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


@wp.kernel
def mark_particle_bits(
    bcoord: wp.array(dtype=wp.vec3i),
    cells: wp.array3d(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    gs: wp.array(dtype=wp.vec3),
    mark: wp.array(dtype=wp.uint64),
    base: int,
):
    """topology_kernels.mark_particle_voxels for active block b (thread = block) as its 8 bit
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


@wp.func
def take_face(own: wp.uint64, own_sign: wp.uint64, nr: wp.uint64, ns: wp.uint64, face: wp.uint64):
    """own with the face bits whose neighbour across the face (nr, ns: its reached and sign
    bits moved onto own's face positions) is reached and of the same sign."""
    return own | (nr & (~(ns ^ own_sign)) & face)


@wp.kernel
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


@wp.kernel
def flip_unreached_bits(reached: wp.array(dtype=wp.uint64), inside_value: float, outside_value: float,
                        phi: wp.array(dtype=float), base: int):
    """topology_kernels.flip_unreached for the 64 voxels of word w (thread = block * 8 + x)."""
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


@wp.kernel
def small_blocks(sign: wp.array(dtype=wp.uint64), reached: wp.array(dtype=wp.uint64), pending: wp.array(dtype=wp.int32),
                 base: int):
    """pending[b] = 1 where block b holds an inside voxel the fill from the bodies (seeds 2) did
    not reach (a voxel of a small component: labels_from_bits labels it), else 0 (thread = block)."""
    b = wp.tid() + base
    left = wp.uint64(0)
    for x in range(BS):
        left = left | ((~reached[b * BS + x]) & (~sign[b * BS + x]))
    pending[b] = wp.where(left != wp.uint64(0), 1, 0)


@wp.kernel
def labels_from_bits(sign: wp.array(dtype=wp.uint64), reached: wp.array(dtype=wp.uint64), labels: wp.array(dtype=wp.int32),
                     base: int):
    """Labels of topology_kernels.init_inside_labels after a fill from the bodies (seeds 2) for
    the 64 voxels of word w: outside -1, reached inside 0 (a component that is not small:
    seed_bits' bodies), the other inside voxels their own t + 1 (the blocks holding those:
    small_blocks)."""
    w = wp.tid() + base
    s = sign[w]
    left = (~reached[w]) & (~s)
    for q in range(BS * BS):
        t = w * BS * BS + q
        lab = LABEL_NONE
        if ((s >> wp.uint64(q)) & wp.uint64(1)) == wp.uint64(0):
            lab = 0
            if ((left >> wp.uint64(q)) & wp.uint64(1)) != wp.uint64(0):
                lab = t + 1
        labels[t] = lab


@wp.kernel
def seed_large_labels(phi: wp.array(dtype=float), mark: wp.array(dtype=wp.int32), min_count: int,
                      labels: wp.array(dtype=wp.int32), base: int):
    """The voxel path's counterpart of seed_bits' large pieces (thread = block; its int32 marks
    and topology_kernels.init_inside_labels' labels): label 0 for the inside voxels of a block
    whose inside voxels are one piece holding at least min_count particles' voxels, so the
    min-label sweeps start from 0 across a water sheet instead of carrying one least index
    over all of it (a 1M-particle random sheet on an H200: 158 rounds, 271 ms)."""
    b = wp.tid() + base
    s = vec8u(wp.uint64(0))
    marked = int(0)
    for x in range(BS):
        w = wp.uint64(0)
        for q in range(BS * BS):
            t = b * BV + x * BS * BS + q
            if phi[t] > 0.0:
                w = w | bit(q)
            elif mark[t] != 0:
                marked += 1
        s[x] = w
    if large_piece(s, marked, min_count):
        for q in range(BV):
            if phi[b * BV + q] <= 0.0:
                labels[b * BV + q] = 0


@wp.kernel
def sweep_min_labels_blocks(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    labels: wp.array(dtype=wp.int32),
    active: wp.array(dtype=wp.int32),
    changed: wp.array(dtype=wp.int32),
    moved: wp.array(dtype=wp.int32),
    base: int,
):
    """topology_kernels.sweep_min_labels along x, y and z for the 64 lines of block b (thread =
    block), again until no label in the block moves (a label then crosses the block in one
    round, not one line sweep a round). The blocks left out (active[b] == 0: those without a
    small component, and after the first round those where nothing moved nearby) cost a thread
    each instead of 64 (a thread per line cost ~1 ms a launch over 2.1 M voxels' lines, one
    thread); moved[b] = 1 where a label was lowered. The lines run in another order than on a
    GPU, which the min-label sweeps allow: they end at each component's least label whatever
    the order (sparse._remove_small)."""
    b = wp.tid() + base
    if active[b] == 0:
        return
    count = int(0)
    while True:  # the block's own fixpoint: the three axes' sweeps until none lowers a label
        now = int(0)
        for ax in range(3):
            for l in range(BS * BS):
                now += sweep_min_line(bcoord, bmap, labels, ax, b, l)
        count += now
        if now == 0:
            break
    if count > 0:
        wp.atomic_add(changed, 0, count)
        moved[b] = 1

