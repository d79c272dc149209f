"""Redistancing a block per thread (its 64 lines along z in turn): the CPU path of :mod:`mpmfx.surface.redistance_kernels`
and of the renormalise / average steps before it (mpmfx.surface.sparse._distance).

Each kernel does per voxel what the voxel kernels do, with the same arithmetic; the line's
neighbour lines are read once into registers instead of through a block-map lookup per voxel.
"""

import warp as wp

from mpmfx.surface.line_kernels import block_faces, fmax, fmin, line_neighbours, line_sides, neighbour_rows, vec8, vmax, vmin
from mpmfx.surface.redistance_kernels import axis_inv2, crossing_fraction, frozen_distance
from mpmfx.surface.sparse_kernels import BS

vec64i = wp.types.vector(length=64, dtype=wp.int32)
vec8u = wp.types.vector(length=8, dtype=wp.uint64)
# masks of a word of eikonal_lines' changed bits (bit y * 8 + z of a block's word x)
Z_FIRST = wp.constant(wp.uint64(0x0101010101010101))  # z = 0 of each line
Z_LOW = wp.constant(wp.uint64(0x7F7F7F7F7F7F7F7F))  # z = 0..6
Z_HIGH = wp.constant(wp.uint64(0xFEFEFEFEFEFEFEFE))  # z = 1..7
BYTE = wp.constant(wp.uint64(0xFF))

# forward only: nothing differentiates these kernels, and their adjoints lengthened the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


@wp.kernel
def crossing_average_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    d1: wp.array(dtype=vec8),
    clip: float,
    frozen: wp.array(dtype=wp.int32),
    out: wp.array(dtype=vec8),
    base: int,
):
    """The second renormalise and the average of _distance: out = (d1 + renormalise(d1)) / 2 as
    sparse_kernels.renormalise and average_into give it, and frozen = 1 at voxels with a
    6-neighbour of the other sign (tiles +-clip). Renormalising keeps each sign, so the
    crossings are d1's. (It used to average only the frozen voxels, the only values
    init_eikonal read; its plane start now reads the frozen voxels' same-sign neighbours too.)
    d1 and out are vec8 rows (line_kernels.rows), as in line_kernels.renormalise_lines."""
    b = wp.tid() + base
    faces = block_faces(bmap, bcoord[b])
    for l in range(64):
        r = b * 64 + l
        sides = line_sides(faces, l // BS, l - (l // BS) * BS)
        xm, xp, ym, yp, lo, hi = neighbour_rows(d1, sides, r, l, clip, -clip)
        dx = xp - xm
        dy = yp - ym
        dz = hi - lo
        own = d1[r]
        # a neighbour of the other sign: a positive voxel has one <= 0 where the least of the
        # six is, a voxel <= 0 one > 0 where the largest is (no value is NaN); the least and
        # largest as vec8 operations, where a compare per neighbour and voxel compiled to
        # scalar compares and sets (90 of the line's ~200 instructions)
        mn = vmin(vmin(xm, xp), vmin(vmin(ym, yp), vmin(lo, hi)))
        mx = vmax(vmax(xm, xp), vmax(vmax(ym, yp), vmax(lo, hi)))
        res = vec8(0.0)
        for z in range(BS):
            v = own[z]
            # the max and the clamp as compares and selects (fmax, fmin: no value is NaN), the
            # same bits (this kernel alone, one thread, best of 9: lattice sphere / torus
            # "fine" 10.6 / 14.7 -> 9.2 / 12.8 ms, with the flags branch-free)
            frozen[r * BS + z] = wp.where(v > 0.0, wp.where(mn[z] <= 0.0, 1, 0), wp.where(mx[z] > 0.0, 1, 0))
            grad = 0.5 * wp.length(wp.vec3(dx[z], dy[z], dz[z]))
            d2 = fmin(fmax(v / fmax(grad, 0.05) * 1.0, -clip), clip)
            res[z] = 0.5 * (v + d2)
        out[r] = res


@wp.kernel
def init_eikonal_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    clip: float,
    plane: int,
    find: int,
    frozen: wp.array(dtype=wp.int32),
    dist: wp.array(dtype=float),
    dist2: wp.array(dtype=float),
    changed: wp.array(dtype=wp.uint64),
    fbits: wp.array(dtype=wp.uint64),
    base: int,
):
    """redistance_kernels.init_eikonal (tiles +-clip) on one block (thread = block), into both
    buffers of the sweeps (dist, dist2); frozen given (crossing_average_lines, find = 0) or
    found here (find = 1: a 6-neighbour of the other sign, as init_eikonal). changed and fbits:
    the frozen voxels as a block's 8 words (eikonal_lines' layout: word x, bit y * 8 + z; fbits
    is what eikonal_lines reads instead of the voxels' flags). A voxel that neither is nor touches a frozen one holds
    +-clip, as do all its neighbours (tiles too), and a sweep leaves it at +-clip: for the
    first sweep (eikonal_lines) the frozen voxels are the ones that changed."""
    b = wp.tid() + base
    faces = block_faces(bmap, bcoord[b])
    word = wp.uint64(0)
    for l in range(64):
        tid = b * 64 + l
        lj = l - (l // BS) * BS
        sides = line_sides(faces, l // BS, lj)
        fz = int(0)
        for z in range(BS):
            t = tid * BS + z
            v = phi[t]
            d = wp.where(v > 0.0, clip, -clip)
            if find != 0 or frozen[t] != 0:
                n = line_neighbours(phi, sides, t, l, z, clip, -clip)
                inv2 = wp.vec3(0.0)
                near = float(1.0)
                cross = int(0)
                for q in range(6):
                    f = crossing_fraction(v, n[q])
                    if f <= 1.0:
                        cross = 1
                        near = wp.min(near, f)
                    inv2[q // 2] = axis_inv2(v, n[q], inv2[q // 2])
                if find != 0:
                    frozen[t] = cross
                else:
                    cross = 1  # frozen given
                if cross != 0:
                    fz = fz | (1 << z)
                    d = frozen_distance(v, inv2, near, plane)
            dist[t] = d
            dist2[t] = d
        word = word | (wp.uint64(fz) << wp.uint64(lj * BS))
        if lj == BS - 1:
            changed[tid // BS] = word
            fbits[tid // BS] = word
            word = wp.uint64(0)


@wp.func
def eikonal_row(xm: vec8, xp: vec8, ym: vec8, yp: vec8, lo: vec8, hi: vec8, v: vec8, clip: float):
    """redistance_kernels.eikonal_update of the 8 voxels of a row (along z) from their
    neighbours' rows, branch-free: all three candidates are computed and the one
    eikonal_update's branches pick is kept, each with eikonal_update's arithmetic per voxel
    (the same bits). The branches depend on the data (the sorted axis distances), so they
    mispredicted; as vec8 operations the 8 voxels run side by side. The mins and maxes are a
    compare and a select each (vmin, vmax, fmin: the same values, as no distance is NaN) where
    wp.min's NaN checks made each a compare, an and and a blend on the line's dependency chain
    (11 captured sweeps, 100k lattice "fine", one thread, alternating: sphere 57 -> 46 ms,
    torus 81 -> 70, bitwise the same)."""
    ax = vmin(wp.abs(xm), wp.abs(xp))
    ay = vmin(wp.abs(ym), wp.abs(yp))
    az = vmin(wp.abs(lo), wp.abs(hi))
    a0 = vmin(ax, vmin(ay, az))
    a2 = vmax(ax, vmax(ay, az))
    a1 = ax + ay + az - a0 - a2
    d = a0 - a1
    q2 = vmax(vec8(2.0) - wp.cw_mul(d, d), vec8(0.0))
    s = a0 + a1 + a2
    q3 = vmax(wp.cw_mul(s, s) - 3.0 * (wp.cw_mul(a0, a0) + wp.cw_mul(a1, a1) + wp.cw_mul(a2, a2) - vec8(1.0)), vec8(0.0))
    av = wp.abs(v)
    out = vec8(0.0)
    for z in range(BS):
        u = a0[z] + 1.0
        u2 = 0.5 * (a0[z] + a1[z] + wp.sqrt(q2[z]))
        u3 = (s[z] + wp.sqrt(q3[z])) / 3.0
        u = wp.where(u > a1[z], wp.where(u2 > a2[z], u3, u2), u)
        u = fmin(fmin(u, av[z]), clip)
        out[z] = wp.where(v[z] > 0.0, u, -u)
    return out


@wp.func
def word_or_tile(words: wp.array(dtype=wp.uint64), code: int, x: int):
    """Word x (0..7) of the block with code `code` (eikonal_lines' layout), 0 for a tile (a
    tile's values never change)."""
    w = wp.uint64(0)
    if code >= 0:
        w = words[code * BS + x]
    return w


@wp.kernel
def eikonal_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=vec8),
    fbits: wp.array(dtype=wp.uint64),
    out_v: float,
    in_v: float,
    clip: float,
    dst: wp.array(dtype=vec8),
    was: wp.array(dtype=wp.uint64),
    now: wp.array(dtype=wp.uint64),
    base: int,
):
    """redistance_kernels.eikonal_sweep on the 64 lines along z of one block (thread = block);
    src and dst: the distance as vec8 rows along z (line_kernels.rows), so a line and its x and
    y neighbour lines are one load each.

    was / now: bit z set where the previous / this sweep changed voxel z (before the first
    sweep: the frozen voxels, see init_eikonal_lines); fbits: bit z set where voxel z is
    frozen. Each is a block's 8 words of 64 bits, word x holding line (x, y)'s 8 bits at
    y * 8 + z (bitfill_kernels' layout), so a line's bits are one byte. A voxel whose 6
    neighbours and itself did not change in the previous sweep would compute what it holds,
    and with src and dst swapped every sweep dst holds the values of two sweeps ago, the same
    ones: it is skipped. Only the lines at the moving front work, and the result is the plain
    Jacobi sweep's. Such a line updates all 8 voxels (eikonal_row) and keeps src's value where
    its voxel is frozen; a skipped voxel's update is the value it holds (by the rule above, and
    before the first sweep a voxel away from the frozen ones holds +-clip, which its update
    gives: init_eikonal_lines), bit for bit."""
    b = wp.tid() + base
    faces = block_faces(bmap, bcoord[b])
    r0 = b * 64
    w0 = b * BS
    # which voxels need work, a word (8 lines) at a time: the z neighbours are the word shifted
    # by one within each byte, the y neighbours by a byte, the x neighbours the next words, the
    # face neighbours' words shifted onto this block's face (a line at a time this cost ~3 ms a
    # sweep of 2800 blocks whether or not a line worked: ~17 ns a line, a third of the sweeps)
    need = vec8u(wp.uint64(0))
    frz = vec8u(wp.uint64(0))
    for x in range(BS):
        mine = was[w0 + x]
        n = mine | ((mine << wp.uint64(1)) & Z_HIGH) | ((mine >> wp.uint64(1)) & Z_LOW) | (mine << wp.uint64(8)) | (mine >> wp.uint64(8))
        if x > 0:
            n = n | was[w0 + x - 1]
        else:
            n = n | word_or_tile(was, faces[0], BS - 1)
        if x < BS - 1:
            n = n | was[w0 + x + 1]
        else:
            n = n | word_or_tile(was, faces[1], 0)
        n = n | (word_or_tile(was, faces[2], x) >> wp.uint64(56)) | (word_or_tile(was, faces[3], x) << wp.uint64(56))
        n = n | ((word_or_tile(was, faces[4], x) >> wp.uint64(7)) & Z_FIRST) | ((word_or_tile(was, faces[5], x) & Z_FIRST) << wp.uint64(7))
        f = fbits[w0 + x]
        frz[x] = f
        need[x] = n & (~f)
    # first the lines that work, listed without a branch on it (the list only advances where
    # one does), then those lines back to back: a branch per line on `need` mispredicted and
    # laid each working line's long dependency chain bare; listed, consecutive lines overlap
    # (the sweeps alone, 11 captured sweeps, 100k lattice "fine", best of 5, one thread: sphere
    # 74 -> 56 ms, torus 116 -> 88; dst and the changed bits bitwise the same)
    todo = vec64i(0)
    cnt = int(0)
    for x in range(BS):
        n = need[x]
        for y in range(BS):
            todo[cnt] = x * BS + y
            cnt += wp.where(((n >> wp.uint64(y * BS)) & BYTE) != wp.uint64(0), 1, 0)
    moved_words = vec8u(wp.uint64(0))
    # two lines at a time: a line's update is one long dependency chain (compares, two square
    # roots, a division), and with its neighbour rows loaded first the two chains interleave in
    # one stretch of code without a branch (the sweeps alone, 11 captured sweeps, 100k lattice
    # "fine", one thread, best of 12 alternating, two runs: sphere 37.7-39.4 -> 33.2-35.9 ms,
    # torus 65.8-71.0 -> 55.6-60.5; bitwise the same)
    k = int(0)
    while k + 1 < cnt:
        l1 = todo[k]
        l2 = todo[k + 1]
        k += 2
        t1 = r0 + l1
        t2 = r0 + l2
        i1 = l1 // BS
        j1 = l1 - i1 * BS
        i2 = l2 // BS
        j2 = l2 - i2 * BS
        own1 = src[t1]
        own2 = src[t2]
        xm1, xp1, ym1, yp1, lo1, hi1 = neighbour_rows(src, line_sides(faces, i1, j1), t1, l1, out_v, in_v)
        xm2, xp2, ym2, yp2, lo2, hi2 = neighbour_rows(src, line_sides(faces, i2, j2), t2, l2, out_v, in_v)
        u1 = eikonal_row(xm1, xp1, ym1, yp1, lo1, hi1, own1, clip)
        u2 = eikonal_row(xm2, xp2, ym2, yp2, lo2, hi2, own2, clip)
        f1 = int((frz[i1] >> wp.uint64(j1 * BS)) & BYTE)
        f2 = int((frz[i2] >> wp.uint64(j2 * BS)) & BYTE)
        m1 = int(0)
        m2 = int(0)
        for z in range(BS):
            keep1 = wp.where((f1 >> z) & 1 != 0, own1[z], u1[z])
            keep2 = wp.where((f2 >> z) & 1 != 0, own2[z], u2[z])
            u1[z] = keep1
            u2[z] = keep2
            m1 = m1 | wp.where(keep1 != own1[z], 1 << z, 0)
            m2 = m2 | wp.where(keep2 != own2[z], 1 << z, 0)
        dst[t1] = u1
        dst[t2] = u2
        moved_words[i1] = moved_words[i1] | (wp.uint64(m1) << wp.uint64(j1 * BS))
        moved_words[i2] = moved_words[i2] | (wp.uint64(m2) << wp.uint64(j2 * BS))
    while k < cnt:
        l = todo[k]
        k += 1
        tid = r0 + l
        li = l // BS
        lj = l - li * BS
        sides = line_sides(faces, li, lj)
        own = src[tid]
        xm, xp, ym, yp, lo, hi = neighbour_rows(src, sides, tid, l, out_v, in_v)
        u = eikonal_row(xm, xp, ym, yp, lo, hi, own, clip)
        # a skipped voxel's update is the value it holds (above): only the frozen ones keep
        # src's value
        fz = int((frz[li] >> wp.uint64(lj * BS)) & BYTE)
        moved = int(0)
        for z in range(BS):
            keep = wp.where((fz >> z) & 1 != 0, own[z], u[z])
            u[z] = keep
            moved = moved | wp.where(keep != own[z], 1 << z, 0)
        dst[tid] = u
        moved_words[li] = moved_words[li] | (wp.uint64(moved) << wp.uint64(lj * BS))
    for x in range(BS):
        now[w0 + x] = moved_words[x]
