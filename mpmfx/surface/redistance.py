"""Redistance pass: the field as a signed distance over the narrow band (voxels).

The Zhu-Bridson field is a distance only near its zero level (it flattens to -r inside), so
blurring it would move curved surfaces outward once the blur reached the flat part. Here the
voxels next to the zero crossing keep their first-order distance, and the rest of the band is
filled by Jacobi sweeps of the Eikonal equation |grad phi| = 1 (the fast iterative method,
upwind, one voxel of progress per sweep), so the smoothing that follows sees a true distance.

GPU: a voxel (init_eikonal) or a line (eikonal_sweep) per thread. CPU: a block per thread, its
64 lines along z in turn, the line's neighbour lines read once into registers; the frozen and
changed voxels as bit words.
"""

from __future__ import annotations

import math

import warp as wp

from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import launch_blocks, launch_nonempty, split
from mpmfx.surface.lines import (
    block_faces,
    fmax,
    fmin,
    line_neighbours,
    line_sides,
    neighbour_rows,
    rows,
    vec8,
    vmax,
    vmin,
)
from mpmfx.surface.renormalise import renormalise_by_block, renormalise_by_voxel
from mpmfx.surface.voxels import BS, BV, line_value, line_z, side_line, step_get, voxel_of

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


@wp.kernel
def average_into(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    """a = (a + b) / 2."""
    t = wp.tid()
    a[t] = 0.5 * (a[t] + b[t])


@wp.kernel
def add_scalar(a: wp.array(dtype=float), value: float):
    t = wp.tid()
    a[t] = a[t] + value


@wp.func
def crossing_fraction(v: float, u: float):
    """|v| / (|v| + |u|): the fraction of the way from v to the zero crossing interpolated
    towards its neighbour u, where u has the other sign; 2 (none) where it has v's."""
    f = float(2.0)
    if (u > 0.0) != (v > 0.0):
        f = wp.abs(v) / wp.max(wp.abs(v) + wp.abs(u), 1.0e-12)
    return f


@wp.func
def axis_inv2(v: float, u: float, inv2: float):
    """max(inv2, 1 / t^2), t = v / (v - u) the zero level's distance from v along the axis
    towards its neighbour u by linear interpolation (t <= 1: u has the other sign) or
    extrapolation (t > 1: u has v's sign but is nearer zero); inv2 where the line moves away
    from zero. 1 / t^2 is continuous as u passes through zero, so the plane start does not jump
    when a crossing appears on another axis between frames."""
    out = inv2
    if (u > 0.0) != (v > 0.0):
        f = wp.abs(v) / wp.max(wp.abs(v) + wp.abs(u), 1.0e-12)
        out = wp.max(inv2, 1.0 / wp.max(f * f, 1.0e-24))
    elif wp.abs(u) < wp.abs(v):
        g = (wp.abs(v) - wp.abs(u)) / wp.abs(v)
        out = wp.max(inv2, g * g)
    return out


@wp.func
def frozen_distance(v: float, inv2: wp.vec3, near: float, plane: int):
    """The start value (v's sign) of a voxel next to the zero crossing. plane != 0: its distance
    to the plane through the crossings interpolated along each axis (inv2[a] = 1 / the nearest
    one's fraction^2 along axis a: axis_inv2), 1 / sqrt(sum inv2): slope 1 across the crossing
    whatever the field's slope there, the crossings where linear interpolation puts them on an
    axis-aligned face. plane = 0: |v|, at most the nearest axis crossing `near` (for a field
    that is a distance already: the closing's grown one)."""
    d = wp.min(wp.abs(v), near)
    if plane != 0:
        d = 1.0 / wp.sqrt(inv2[0] + inv2[1] + inv2[2])
    return wp.where(v > 0.0, d, -d)


@wp.kernel
def init_eikonal(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    clip: float,
    plane: int,
    frozen: wp.array(dtype=wp.int32),
    dist: wp.array(dtype=float),
    base: int,
):
    """Voxels with a 6-neighbour of the other sign (frozen = 1) start at frozen_distance; the
    others at +-clip with phi's sign. With plane = 1 (the raw field, distance_by_voxel) that is
    the distance to the plane through the axis crossings, not phi itself (at most the nearest
    axis crossing): the raw field's slope across its crossing is not 1 (0.97 on a flat lattice
    face), so that distance would have a kink there, and each smoothing step would move flat
    faces out across it. plane = 0 keeps phi (the closing's grown distance: redistancing it then changes
    nothing on a smooth surface, and the closing's gate leaves lattices where they were)."""
    t = wp.tid() + base
    c = voxel_of(t, bcoord)
    v = phi[t]
    inv2 = wp.vec3(0.0)
    near = float(1.0)
    cross = int(0)
    for n in range(6):
        u = step_get(bmap, phi, t, c, n // 2, 2 * (n % 2) - 1, out_v, in_v)
        f = crossing_fraction(v, u)
        if f <= 1.0:
            cross = 1
            near = wp.min(near, f)
        inv2[n // 2] = axis_inv2(v, u, inv2[n // 2])
    frozen[t] = cross
    if cross == 1:
        dist[t] = frozen_distance(v, inv2, near, plane)
    else:
        dist[t] = wp.where(v > 0.0, clip, -clip)


@wp.kernel
def eikonal_sweep(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=float),
    frozen: wp.array(dtype=wp.int32),
    out_v: float,
    in_v: float,
    clip: float,
    dst: wp.array(dtype=float),
    base: int,
):
    """One Jacobi sweep of |grad phi| = 1 (upwind, unit spacing) on |phi|, keeping each sign, on
    the 8 voxels of one line along z (thread = line, 64 a block): the neighbour lines and the
    blocks below and above are found once for the line, not at every voxel on a block face
    (each voxel gets what a voxel per thread with step_get did, bit for bit)."""
    q = wp.tid() + base
    b = q // 64
    l = q - b * 64
    x = l // BS
    y = l - x * BS
    bc = bcoord[b]
    t0 = b * BV + l * BS
    xm = side_line(bmap, bc, b, x - 1, y, 0)
    xp = side_line(bmap, bc, b, x + 1, y, 0)
    ym = side_line(bmap, bc, b, x, y - 1, 0)
    yp = side_line(bmap, bc, b, x, y + 1, 0)
    zm = side_line(bmap, bc, b, x, y, -1)
    zp = side_line(bmap, bc, b, x, y, 1)
    for k in range(BS):
        t = t0 + k
        v = src[t]
        if frozen[t] != 0:
            dst[t] = v
            continue
        a = wp.vec3(
            wp.min(wp.abs(line_value(src, xm, k, out_v, in_v)), wp.abs(line_value(src, xp, k, out_v, in_v))),
            wp.min(wp.abs(line_value(src, ym, k, out_v, in_v)), wp.abs(line_value(src, yp, k, out_v, in_v))),
            wp.min(
                wp.abs(line_z(src, t0, zm, zp, k - 1, out_v, in_v)), wp.abs(line_z(src, t0, zm, zp, k + 1, out_v, in_v))
            ),
        )
        dst[t] = eikonal_update(a, v, clip)


@wp.func
def eikonal_update(a: wp.vec3, v: float, clip: float):
    """The upwind solution of |grad u| = 1 from the smaller neighbour magnitude per axis `a`,
    at most |v| and clip, with v's sign."""
    # sort a[0] <= a[1] <= a[2]
    a0 = wp.min(a[0], wp.min(a[1], a[2]))
    a2 = wp.max(a[0], wp.max(a[1], a[2]))
    a1 = a[0] + a[1] + a[2] - a0 - a2
    u = a0 + 1.0
    if u > a1:
        u = 0.5 * (a0 + a1 + wp.sqrt(wp.max(2.0 - (a0 - a1) * (a0 - a1), 0.0)))
        if u > a2:
            s = a0 + a1 + a2
            u = (s + wp.sqrt(wp.max(s * s - 3.0 * (a0 * a0 + a1 * a1 + a2 * a2 - 1.0), 0.0))) / 3.0
    u = wp.min(wp.min(u, wp.abs(v)), clip)
    return wp.where(v > 0.0, u, -u)


vec64i = wp.types.vector(length=64, dtype=wp.int32)

vec8u = wp.types.vector(length=8, dtype=wp.uint64)


# masks of a word of eikonal_lines' changed bits (bit y * 8 + z of a block's word x)
Z_FIRST = wp.constant(wp.uint64(0x0101010101010101))  # z = 0 of each line

Z_LOW = wp.constant(wp.uint64(0x7F7F7F7F7F7F7F7F))  # z = 0..6

Z_HIGH = wp.constant(wp.uint64(0xFEFEFEFEFEFEFEFE))  # z = 1..7

BYTE = wp.constant(wp.uint64(0xFF))


@cpu_kernel
def crossing_average_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    d1: wp.array(dtype=vec8),
    clip: float,
    frozen: wp.array(dtype=wp.int32),
    out: wp.array(dtype=vec8),
    base: int,
):
    """The second renormalise and the average of distance_by_voxel: out = (d1 + renormalise(d1)) / 2 as
    renormalise.renormalise and average_into give it, and frozen = 1 at voxels with a
    6-neighbour of the other sign (tiles +-clip). Renormalising keeps each sign, so the
    crossings are d1's. (Every voxel is averaged, not only the frozen ones: init_eikonal's
    plane start reads the frozen voxels' same-sign neighbours too.)
    d1 and out are vec8 rows (lines.rows), as in renormalise.renormalise_lines."""
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
            # same bits, with the flags branch-free
            frozen[r * BS + z] = wp.where(v > 0.0, wp.where(mn[z] <= 0.0, 1, 0), wp.where(mx[z] > 0.0, 1, 0))
            grad = 0.5 * wp.length(wp.vec3(dx[z], dy[z], dz[z]))
            d2 = fmin(fmax(v / fmax(grad, 0.05) * 1.0, -clip), clip)
            res[z] = 0.5 * (v + d2)
        out[r] = res


@cpu_kernel
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
    """init_eikonal (tiles +-clip) on one block (thread = block), into both
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
    """eikonal_update of the 8 voxels of a row (along z) from their
    neighbours' rows, branch-free: all three candidates are computed and the one
    eikonal_update's branches pick is kept, each with eikonal_update's arithmetic per voxel
    (the same bits). The branches depend on the data (the sorted axis distances), so they
    mispredicted; as vec8 operations the 8 voxels run side by side. The mins and maxes are a
    compare and a select each (vmin, vmax, fmin: the same values, as no distance is NaN) where
    wp.min's NaN checks would make each a compare, an and and a blend on the line's dependency
    chain (bitwise the same)."""
    ax = vmin(wp.abs(xm), wp.abs(xp))
    ay = vmin(wp.abs(ym), wp.abs(yp))
    az = vmin(wp.abs(lo), wp.abs(hi))
    a0 = vmin(ax, vmin(ay, az))
    a2 = vmax(ax, vmax(ay, az))
    a1 = ax + ay + az - a0 - a2
    d = a0 - a1
    q2 = vmax(vec8(2.0) - wp.cw_mul(d, d), vec8(0.0))
    s = a0 + a1 + a2
    q3 = vmax(
        wp.cw_mul(s, s) - 3.0 * (wp.cw_mul(a0, a0) + wp.cw_mul(a1, a1) + wp.cw_mul(a2, a2) - vec8(1.0)), vec8(0.0)
    )
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


@cpu_kernel
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
    """eikonal_sweep on the 64 lines along z of one block (thread = block);
    src and dst: the distance as vec8 rows along z (lines.rows), so a line and its x and
    y neighbour lines are one load each.

    was / now: bit z set where the previous / this sweep changed voxel z (before the first
    sweep: the frozen voxels, see init_eikonal_lines); fbits: bit z set where voxel z is
    frozen. Each is a block's 8 words of 64 bits, word x holding line (x, y)'s 8 bits at
    y * 8 + z (bitwords' layout), so a line's bits are one byte. A voxel whose 6
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
        n = (
            mine
            | ((mine << wp.uint64(1)) & Z_HIGH)
            | ((mine >> wp.uint64(1)) & Z_LOW)
            | (mine << wp.uint64(8))
            | (mine >> wp.uint64(8))
        )
        if x > 0:
            n = n | was[w0 + x - 1]
        else:
            n = n | word_or_tile(was, faces[0], BS - 1)
        if x < BS - 1:
            n = n | was[w0 + x + 1]
        else:
            n = n | word_or_tile(was, faces[1], 0)
        n = n | (word_or_tile(was, faces[2], x) >> wp.uint64(56)) | (word_or_tile(was, faces[3], x) << wp.uint64(56))
        n = (
            n
            | ((word_or_tile(was, faces[4], x) >> wp.uint64(7)) & Z_FIRST)
            | ((word_or_tile(was, faces[5], x) & Z_FIRST) << wp.uint64(7))
        )
        f = fbits[w0 + x]
        frz[x] = f
        need[x] = n & (~f)
    # first the lines that work, listed without a branch on it (the list only advances where
    # one does), then those lines back to back: a branch per line on `need` would mispredict
    # and lay each working line's long dependency chain bare; listed, consecutive lines overlap
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
    # one stretch of code without a branch
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


def sweep_count(clip: float, read: float) -> int:
    """Jacobi sweeps of |grad phi| = 1 that leave the values within `read` voxels of the zero
    level as more sweeps would, to rounding. A sweep advances one voxel along each axis, so from
    the frozen voxels (within one of the zero level) a face at any slant is converged to read
    after sqrt(3) (read - 1) sweeps, and along an axis to clip after clip sweeps; further out the
    values step up to +-clip (the final renormalise keeps those at the band's value)."""
    return min(int(math.ceil(clip)), int(math.ceil(math.sqrt(3.0) * (read - 1.0)))) + 1


def distance_by_voxel(bcoord, bmap, phi, tiles, clip: float, read: float):
    """The raw field as a distance (voxels, clipped to +-clip) that blurs without moving its zero
    level, a voxel per thread. phi / |grad phi| has slope 1 at the zero level but, where phi is
    convex across the surface (Zhu-Bridson is), the opposite curvature of phi itself, so a blur
    would move the surface outward as far as it would move the raw field inward. Renormalising
    that once more flips the curvature back; the mean of the two is straight to second order.
    The raw field is a distance only near its zero level (it flattens to -r inside, and the
    renormalised values there are no distance either): its zero crossings are kept, the voxels
    next to them start at their distance to the plane through the axis crossings (init_eikonal,
    plane = 1: the field's own slope there is not 1, and a kink at the crossing would move flat
    faces out under the blur), and the rest of the band is recomputed from them (|grad phi| = 1)."""
    nvox = phi.shape[0]
    d1, d2 = wp.empty_like(phi), wp.empty_like(phi)
    renormalise_by_voxel(bcoord, bmap, phi, tiles, 1.0, clip, d1)
    if nvox == 0:
        return d1
    frozen = wp.empty(nvox, dtype=wp.int32)
    a, b = wp.empty_like(phi), wp.empty_like(phi)
    renormalise_by_voxel(bcoord, bmap, d1, (clip, -clip), 1.0, clip, d2)
    launch_nonempty(wp, average_into, nvox, [d1, d2])
    split(wp, init_eikonal, nvox, [bcoord, bmap, d1, clip, -clip, clip, 1, frozen, a])
    return sweeps_by_voxel(bcoord, bmap, a, b, frozen, clip, read)


def distance_by_block(bcoord, bmap, phi, tiles, clip: float, read: float):
    """distance_by_voxel, a block per thread: the second renormalise and the average in one pass
    with the frozen flags, which init_eikonal_lines keeps as bits."""
    nvox = phi.shape[0]
    d1, d2 = wp.empty_like(phi), wp.empty_like(phi)
    renormalise_by_block(bcoord, bmap, phi, tiles, 1.0, clip, d1)
    if nvox == 0:
        return d1
    frozen = wp.empty(nvox, dtype=wp.int32)
    a, b = wp.empty_like(phi), wp.empty_like(phi)
    was = wp.empty(nvox // 64, dtype=wp.uint64)  # voxels changed by a sweep, a bit each
    fbits = wp.empty(nvox // 64, dtype=wp.uint64)  # the frozen voxels, a bit each
    launch_blocks(wp, crossing_average_lines, [bcoord, bmap, rows(d1), clip, frozen, rows(d2)])
    launch_blocks(wp, init_eikonal_lines, [bcoord, bmap, d2, clip, 1, 0, frozen, a, b, was, fbits])
    return sweeps_by_block(bcoord, bmap, a, b, was, fbits, clip, read)


def redistance_by_voxel(bcoord, bmap, phi, clip: float, read: float):
    """phi's zero level with a distance around it (a new array, voxels, clipped to +-clip): the
    voxels next to the crossing keep theirs (capped at the crossing interpolated along an axis),
    the rest of the band comes from the Eikonal sweeps, as in distance_by_voxel (tiles read +-clip)."""
    nvox = phi.shape[0]
    frozen = wp.empty(nvox, dtype=wp.int32)
    a, b = wp.empty_like(phi), wp.empty_like(phi)
    split(wp, init_eikonal, nvox, [bcoord, bmap, phi, clip, -clip, clip, 0, frozen, a])
    return sweeps_by_voxel(bcoord, bmap, a, b, frozen, clip, read)


def redistance_by_block(bcoord, bmap, phi, clip: float, read: float):
    """redistance_by_voxel, a block per thread: the frozen flags found too, into both sweep
    buffers, with the changed bits the line sweeps start from."""
    nvox = phi.shape[0]
    frozen = wp.empty(nvox, dtype=wp.int32)
    a, b = wp.empty_like(phi), wp.empty_like(phi)
    was = wp.empty(nvox // 64, dtype=wp.uint64)
    fbits = wp.empty(nvox // 64, dtype=wp.uint64)
    launch_blocks(wp, init_eikonal_lines, [bcoord, bmap, phi, clip, 0, 1, frozen, a, b, was, fbits])
    return sweeps_by_block(bcoord, bmap, a, b, was, fbits, clip, read)


def sweeps_by_voxel(bcoord, bmap, a, b, frozen, clip: float, read: float):
    """Jacobi sweeps of |grad phi| = 1 from the initial distance a (b: the second buffer), a line
    per thread, sweep_count(clip, read) of them; the result (a or b)."""
    for _ in range(sweep_count(clip, read)):
        split(wp, eikonal_sweep, a.shape[0] // BS, [bcoord, bmap, a, frozen, clip, -clip, clip, b])  # a line each
        a, b = b, a
    return a


def sweeps_by_block(bcoord, bmap, a, b, was, fbits, clip: float, read: float):
    """sweeps_by_voxel, a block per thread (b: a copy of a, `was` the voxels init set, fbits the
    frozen ones, a bit per voxel): a line whose neighbourhood did not change is skipped."""
    now = wp.empty(a.shape[0] // 64, dtype=wp.uint64)
    for _ in range(sweep_count(clip, read)):
        launch_blocks(wp, eikonal_lines, [bcoord, bmap, rows(a), fbits, clip, -clip, clip, rows(b), was, now])
        was, now = now, was
        a, b = b, a
    return a
