"""Warp kernels of the sparse surfacer's CPU path: a block of 8^3 voxels per thread, worked
through as 64 lines of 8 voxels.

Warp's CPU backend runs a launch's threads one after another on one core, so there what
counts is the work per voxel, not the thread count: the GPU's layout (a thread per voxel) pays
there for what a GPU hides (index arithmetic, a block-map lookup per neighbour read). Here the
neighbour blocks are looked up once per block, a line's neighbour lines are read once, and the
field gather (mpmfx.surface.line_gather_kernels) fetches each candidate particle once per
block, not once per line of it. Every voxel gets the same arithmetic in the same order as in
the voxel kernels, so the results are theirs bit for bit (tests/surface/test_line_kernels.py).

`base`: the first thread's index, so a launch can be split into chunks run on several CPU
threads (Warp's CPU launches release the GIL; mpmfx.surface.launch).
"""

import warp as wp

from mpmfx.surface.sparse_kernels import BS, BV, TILE_INSIDE, TILE_OUTSIDE, edge_flow_step, edge_limit, flow_taper, gate_cell
from mpmfx.surface.sparse_kernels import block_tile as block_code

vec8 = wp.types.vector(length=8, dtype=wp.float32)

# forward only: nothing differentiates these kernels, and their adjoints lengthened the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


@wp.func
def fmin(a: float, b: float):
    """wp.min for numbers that are never NaN: one compare and select (minps), where wp.min's
    NaN checks cost a compare, an and and a blend of one chain."""
    return wp.where(b < a, b, a)


@wp.func
def fmax(a: float, b: float):
    """wp.max for numbers that are never NaN (as fmin)."""
    return wp.where(b > a, b, a)


@wp.func
def vmin(a: vec8, b: vec8):
    """fmin of each of the 8."""
    r = vec8(0.0)
    for z in range(BS):
        r[z] = wp.where(b[z] < a[z], b[z], a[z])
    return r


@wp.func
def vmax(a: vec8, b: vec8):
    """wp.max of each of the 8 for numbers that are never NaN (as fmin)."""
    r = vec8(0.0)
    for z in range(BS):
        r[z] = wp.where(b[z] > a[z], b[z], a[z])
    return r


@wp.func
def side_code(bmap: wp.array3d(dtype=wp.int32), bc: wp.vec3i, axis: int, sgn: int):
    """block_code of the block next to bc along `axis` (sgn = +-1)."""
    n = wp.vec3i(bc[0], bc[1], bc[2])
    n[axis] = n[axis] + sgn
    return block_code(bmap, n)


@wp.func
def read(data: wp.array(dtype=float), code: int, local: int, out_v: float, in_v: float):
    """Voxel `local` (0..511) of the block with code `code`: its value, or a tile's value."""
    if code >= 0:
        return data[code * BV + local]
    if code == TILE_INSIDE:
        return in_v
    return out_v


@wp.func
def local_index(lc: wp.vec3i):
    return (lc[0] * BS + lc[1]) * BS + lc[2]


@wp.func
def row_or_tile(src: wp.array(dtype=vec8), code: int, r: int, out_v: float, in_v: float):
    """Row r (0..63, its 8 voxels along z) of the block with code `code`, or a tile's value in
    all 8."""
    if code >= 0:
        return src[code * 64 + r]
    if code == TILE_INSIDE:
        return vec8(in_v)
    return vec8(out_v)


@wp.func
def row_steps(axis: int):
    """(row step along `axis`, row step along the other axis of the block's rows) for axis 0
    or 1: a block's row (x, y) is its 8 voxels along z, row x * 8 + y."""
    return wp.where(axis == 0, BS, 1), wp.where(axis == 0, 1, BS)


vec27i = wp.types.vector(length=27, dtype=wp.int32)


@wp.func
def block_codes27(bmap: wp.array3d(dtype=wp.int32), bc: wp.vec3i):
    """block_code of block bc and its 26 neighbours, at (dx + 1) * 9 + (dy + 1) * 3 + dz + 1."""
    codes = vec27i()
    for n in range(27):
        codes[n] = block_code(bmap, wp.vec3i(bc[0] + n // 9 - 1, bc[1] + (n // 3) % 3 - 1, bc[2] + n % 3 - 1))
    return codes


@wp.func
def ext_row(src: wp.array(dtype=vec8), codes: vec27i, x: int, y: int, dz: int, out_v: float, in_v: float):
    """Row (x, y) (x, y in -1..8: the block's own or a neighbour's along x and y) of the block
    dz (-1, 0, 1) along z, as row_or_tile reads it."""
    dx = int(0)
    dy = int(0)
    if x < 0:
        dx = -1
    elif x >= BS:
        dx = 1
    if y < 0:
        dy = -1
    elif y >= BS:
        dy = 1
    r = (x - dx * BS) * BS + (y - dy * BS)
    return row_or_tile(src, codes[(dx + 1) * 9 + (dy + 1) * 3 + dz + 1], r, out_v, in_v)


@wp.func
def shift_down(row: vec8, lo: float):
    """The row's values at z - 1: lo, row[0], ..., row[6]."""
    return vec8(lo, row[0], row[1], row[2], row[3], row[4], row[5], row[6])


@wp.func
def shift_up(row: vec8, hi: float):
    """The row's values at z + 1: row[1], ..., row[7], hi."""
    return vec8(row[1], row[2], row[3], row[4], row[5], row[6], row[7], hi)


@wp.func
def z_pair(src: wp.array(dtype=vec8), codes: vec27i, x: int, y: int, row: vec8, out_v: float, in_v: float):
    """(row at z - 1, row at z + 1) of row (x, y), its ends from the blocks below and above."""
    lo = ext_row(src, codes, x, y, -1, out_v, in_v)[BS - 1]
    hi = ext_row(src, codes, x, y, 1, out_v, in_v)[0]
    return shift_down(row, lo), shift_up(row, hi)


@wp.func
def flow_rows(src: wp.array(dtype=vec8), codes: vec27i, r0: int, r: int, c: vec8, out_v: float, in_v: float):
    """The neighbour values flow_step reads, for the 8 voxels of row r of the block whose rows
    start at r0 (c: the row itself): (x - 1, x + 1, y - 1, y + 1, z - 1, z + 1 rows, fxy, fxz,
    fyz), each the same float as sparse_kernels' `get` reads and combines per voxel."""
    x = r // BS
    y = r % BS
    xm = vec8()
    xp = vec8()
    ym = vec8()
    yp = vec8()
    fxy = vec8()
    if x > 0 and x < BS - 1 and y > 0 and y < BS - 1:  # its row's x and y neighbours are in the block
        xm = src[r0 + r - BS]
        xp = src[r0 + r + BS]
        ym = src[r0 + r - 1]
        yp = src[r0 + r + 1]
        fxy = 0.25 * (src[r0 + r + BS + 1] - src[r0 + r + BS - 1] - src[r0 + r - BS + 1] + src[r0 + r - BS - 1])
    else:
        xm = ext_row(src, codes, x - 1, y, 0, out_v, in_v)
        xp = ext_row(src, codes, x + 1, y, 0, out_v, in_v)
        ym = ext_row(src, codes, x, y - 1, 0, out_v, in_v)
        yp = ext_row(src, codes, x, y + 1, 0, out_v, in_v)
        fxy = 0.25 * (ext_row(src, codes, x + 1, y + 1, 0, out_v, in_v) - ext_row(src, codes, x + 1, y - 1, 0, out_v, in_v)
                      - ext_row(src, codes, x - 1, y + 1, 0, out_v, in_v) + ext_row(src, codes, x - 1, y - 1, 0, out_v, in_v))
    zm, zp = z_pair(src, codes, x, y, c, out_v, in_v)
    xm_down, xm_up = z_pair(src, codes, x - 1, y, xm, out_v, in_v)
    xp_down, xp_up = z_pair(src, codes, x + 1, y, xp, out_v, in_v)
    ym_down, ym_up = z_pair(src, codes, x, y - 1, ym, out_v, in_v)
    yp_down, yp_up = z_pair(src, codes, x, y + 1, yp, out_v, in_v)
    fxz = 0.25 * (xp_up - xp_down - xm_up + xm_down)
    fyz = 0.25 * (yp_up - yp_down - ym_up + ym_down)
    return xm, xp, ym, yp, zm, zp, fxy, fxz, fyz


@wp.kernel
def curvature_flow_lines(bcoord: wp.array(dtype=wp.vec3i), bmap: wp.array3d(dtype=wp.int32), src: wp.array(dtype=vec8),
                         out_v: float, in_v: float, dt: float, band: float, dst: wp.array(dtype=vec8), base: int):
    """sparse_kernels.curvature_flow on one block (thread = block), a row of 8 voxels along z at
    a time: the 26 neighbour blocks are looked up once, a row's neighbour rows read once, and
    sparse_kernels.flow_step's arithmetic runs 8 voxels at a time, the same operations in the
    same order, so the results are the voxel kernel's bit for bit (a block a thread voxel by
    voxel took 19 ms a step at 100k torus lattice "fine", this 10 ms; skipping the rows with no
    value in the band, 14-16 % less again: one step on captured inputs, one thread, best of 21,
    lattice / random torus 7.8 / 13.0 -> 6.7 / 11.3 ms). The voxels where the edge gate is open
    are stepped again by edge_flow_lines."""
    b = wp.tid() + base
    r0 = b * 64
    moves = bool(False)  # a block with no value within `band` of the zero level stays as it is
    for r in range(64):
        row = src[r0 + r]
        for k in range(BS):
            if wp.abs(row[k]) < band:
                moves = True
    if not moves:
        for r in range(64):
            dst[r0 + r] = src[r0 + r]
        return
    codes = block_codes27(bmap, bcoord[b])
    for r in range(64):
        c = src[r0 + r]
        near = bool(False)  # a row with no value within `band` stays as it is (no neighbour read)
        for k in range(BS):
            if wp.abs(c[k]) < band:
                near = True
        if not near:
            dst[r0 + r] = c
            continue
        xm, xp, ym, yp, zm, zp, fxy, fxz, fyz = flow_rows(src, codes, r0, r, c, out_v, in_v)
        # flow_step, 8 voxels at a time (the same operations in the same order for each)
        gx = 0.5 * (xp - xm)
        gy = 0.5 * (yp - ym)
        gz = 0.5 * (zp - zm)
        fxx = xp - 2.0 * c + xm
        fyy = yp - 2.0 * c + ym
        fzz = zp - 2.0 * c + zm
        gxx = wp.cw_mul(gx, gx)
        gyy = wp.cw_mul(gy, gy)
        gzz = wp.cw_mul(gz, gz)
        g2 = gxx + gyy + gzz
        num = (wp.cw_mul(gxx, fxx) + wp.cw_mul(gyy, fyy) + wp.cw_mul(gzz, fzz)
               + 2.0 * (wp.cw_mul(wp.cw_mul(gx, gy), fxy) + wp.cw_mul(wp.cw_mul(gx, gz), fxz) + wp.cw_mul(wp.cw_mul(gy, gz), fyz)))
        lap = fxx + fyy + fzz
        out = vec8()
        for k in range(BS):
            taper = flow_taper(c[k], band)
            nhn = float(0.0)
            if g2[k] > 1.0e-8:
                nhn = num[k] / g2[k]
            out[k] = wp.where(taper == 0.0, c[k], c[k] + taper * dt * (lap[k] - nhn))
        dst[r0 + r] = out


@wp.kernel
def edge_flow_lines(bcoord: wp.array(dtype=wp.vec3i), bmap: wp.array3d(dtype=wp.int32), src: wp.array(dtype=vec8),
                    out_v: float, in_v: float, dt: float, band: float, gate: wp.array(dtype=float), pit: float,
                    dst: wp.array(dtype=vec8), base: int):
    """sparse_kernels.edge_flow after curvature_flow_lines (thread = block): the rows that cross
    an open gate cell read their neighbour rows as curvature_flow_lines does (flow_rows), and
    their voxels in an open cell take sparse_kernels.edge_flow_step, the same values in the
    same operations as the voxel kernel. Kept out of the row kernel: there the edge step's
    code, even in a branch never taken, made the flow twice as slow (one step, captured
    inputs, one thread). A voxel per neighbour read (`get`) instead of rows took 16 ms a step
    on the default shot's water at frame 12 (18k particles, a splash: open gates all over)."""
    b = wp.tid() + base
    shut = bool(True)
    u = int(0)
    while u < 64:  # the block's 2^3-voxel cells: most blocks have no open one
        if gate[b * 64 + u] > 0.0:
            shut = False
        u += 1
    if shut:
        return
    codes = block_codes27(bmap, bcoord[b])
    r0 = b * 64
    for r in range(64):
        g0 = b * 64 + ((r // BS) // 2) * 16 + ((r % BS) // 2) * 4  # the row's first cell (z 0, 1)
        c = src[r0 + r]
        todo = bool(False)
        k = int(0)
        while k < BS:
            if gate[g0 + k // 2] > 0.0 and flow_taper(c[k], band) > 0.0:
                todo = True
            k += 1
        if todo:
            xm, xp, ym, yp, zm, zp, fxy, fxz, fyz = flow_rows(src, codes, r0, r, c, out_v, in_v)
            out = dst[r0 + r]
            k = int(0)
            while k < BS:  # not unrolled: one copy of the edge step
                g8 = gate[g0 + k // 2]
                taper = flow_taper(c[k], band)
                if g8 > 0.0 and taper > 0.0:
                    out[k] = edge_flow_step(c[k], xm[k], xp[k], ym[k], yp[k], zm[k], zp[k], fxy[k], fxz[k], fyz[k], dt, taper, g8, pit)
                k += 1
            dst[r0 + r] = out


@wp.func
def weight_row(src: wp.array(dtype=vec8), code: int, r: int, own: vec8):
    """weight_at for a row: row r of the block with code `code`, 0 on an OUTSIDE tile, the
    voxels' own values `own` on an INSIDE one."""
    if code >= 0:
        return src[code * 64 + r]
    if code == TILE_INSIDE:
        return own
    return vec8(0.0)


@wp.kernel
def blur_weight_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=vec8),
    axis: int,
    dst: wp.array(dtype=vec8),
    base: int,
):
    """sparse_kernels.blur_weight_axis with step 2 on one block (thread = block), 8 voxels at a
    time (src, dst: the weights as vec8 rows along z; along x or y a row's neighbours are whole
    rows, along z a row is a line and its neighbours the row shifted): each voxel gets 0.25
    (2 before) + 0.5 itself + 0.25 (2 after), in that order, a tap on an OUTSIDE tile 0, on an
    INSIDE one the voxel's own value (weight_at)."""
    b = wp.tid() + base
    below = side_code(bmap, bcoord[b], axis, -1)
    above = side_code(bmap, bcoord[b], axis, 1)
    r0 = b * 64
    if axis == 2:
        for l in range(64):
            c = src[r0 + l]
            lo = weight_row(src, below, l, c)
            hi = weight_row(src, above, l, c)
            if below == TILE_INSIDE:  # the taps before voxels 0 and 1 read those voxels
                lo = vec8(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, c[0], c[1])
            if above == TILE_INSIDE:
                hi = vec8(c[6], c[7], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            m2 = vec8(lo[6], lo[7], c[0], c[1], c[2], c[3], c[4], c[5])
            p2 = vec8(c[2], c[3], c[4], c[5], c[6], c[7], hi[0], hi[1])
            dst[r0 + l] = 0.25 * m2 + 0.5 * c + 0.25 * p2
        return
    sa, so = row_steps(axis)
    for o in range(BS):
        c0 = src[r0 + o * so]
        c1 = src[r0 + sa + o * so]
        c2 = src[r0 + 2 * sa + o * so]
        c3 = src[r0 + 3 * sa + o * so]
        c4 = src[r0 + 4 * sa + o * so]
        c5 = src[r0 + 5 * sa + o * so]
        c6 = src[r0 + 6 * sa + o * so]
        c7 = src[r0 + 7 * sa + o * so]
        l6 = weight_row(src, below, 6 * sa + o * so, c0)
        l7 = weight_row(src, below, 7 * sa + o * so, c1)
        h0 = weight_row(src, above, o * so, c6)
        h1 = weight_row(src, above, sa + o * so, c7)
        dst[r0 + o * so] = 0.25 * l6 + 0.5 * c0 + 0.25 * c2
        dst[r0 + sa + o * so] = 0.25 * l7 + 0.5 * c1 + 0.25 * c3
        dst[r0 + 2 * sa + o * so] = 0.25 * c0 + 0.5 * c2 + 0.25 * c4
        dst[r0 + 3 * sa + o * so] = 0.25 * c1 + 0.5 * c3 + 0.25 * c5
        dst[r0 + 4 * sa + o * so] = 0.25 * c2 + 0.5 * c4 + 0.25 * c6
        dst[r0 + 5 * sa + o * so] = 0.25 * c3 + 0.5 * c5 + 0.25 * c7
        dst[r0 + 6 * sa + o * so] = 0.25 * c4 + 0.5 * c6 + 0.25 * h0
        dst[r0 + 7 * sa + o * so] = 0.25 * c5 + 0.5 * c7 + 0.25 * h1


def rows(a):
    """A vec8 view of the float array a (voxels, a block's 512 in order): its rows of 8 voxels
    along z, the same memory (the caller keeps a alive)."""
    import warp

    return warp.array(ptr=a.ptr, shape=(a.shape[0] // BS,), dtype=vec8, device=a.device)


vec6 = wp.types.vector(length=6, dtype=wp.float32)
vec6i = wp.types.vector(length=6, dtype=wp.int32)


@wp.func
def block_faces(bmap: wp.array3d(dtype=wp.int32), bc: wp.vec3i):
    """Codes of the -x, +x, -y, +y, -z, +z face neighbours of block bc (side_code)."""
    c = vec6i(0)
    for n in range(6):
        c[n] = side_code(bmap, bc, n // 2, 2 * (n % 2) - 1)
    return c


@wp.func
def line_sides(faces: vec6i, li: int, lj: int):
    """Codes of the blocks holding the -x, +x, -y, +y, -z, +z neighbours of line (li, lj) of a
    block with face codes `faces` (block_faces) that lie outside it (OUTSIDE where the line is
    not at that face)."""
    c = vec6i(TILE_OUTSIDE)
    if li == 0:
        c[0] = faces[0]
    if li == BS - 1:
        c[1] = faces[1]
    if lj == 0:
        c[2] = faces[2]
    if lj == BS - 1:
        c[3] = faces[3]
    c[4] = faces[4]
    c[5] = faces[5]
    return c


@wp.func
def line_neighbours(src: wp.array(dtype=float), sides: vec6i, t: int, l: int, z: int, out_v: float, in_v: float):
    """`get` of the -x, +x, -y, +y, -z, +z neighbours of voxel t = line l's voxel z (sides from
    line_sides)."""
    li = l // BS
    lj = l - li * BS
    n = vec6(0.0)
    if li > 0:
        n[0] = src[t - BS * BS]
    else:
        n[0] = read(src, sides[0], ((BS - 1) * BS + lj) * BS + z, out_v, in_v)
    if li < BS - 1:
        n[1] = src[t + BS * BS]
    else:
        n[1] = read(src, sides[1], lj * BS + z, out_v, in_v)
    if lj > 0:
        n[2] = src[t - BS]
    else:
        n[2] = read(src, sides[2], (li * BS + BS - 1) * BS + z, out_v, in_v)
    if lj < BS - 1:
        n[3] = src[t + BS]
    else:
        n[3] = read(src, sides[3], li * BS * BS + z, out_v, in_v)
    if z > 0:
        n[4] = src[t - 1]
    else:
        n[4] = read(src, sides[4], l * BS + BS - 1, out_v, in_v)
    if z < BS - 1:
        n[5] = src[t + 1]
    else:
        n[5] = read(src, sides[5], l * BS, out_v, in_v)
    return n


@wp.func
def neighbour_rows(src: wp.array(dtype=vec8), sides: vec6i, r: int, l: int, out_v: float, in_v: float):
    """line_neighbours for the 8 voxels of row r (= block * 64 + line l) at once, from vec8
    rows (rows): the rows of the -x, +x, -y, +y neighbours, and the row shifted towards -z and
    +z (sides from line_sides)."""
    li = l // BS
    lj = l - li * BS
    own = src[r]
    xm = vec8(0.0)
    if li > 0:
        xm = src[r - BS]
    else:
        xm = row_or_tile(src, sides[0], (BS - 1) * BS + lj, out_v, in_v)
    xp = vec8(0.0)
    if li < BS - 1:
        xp = src[r + BS]
    else:
        xp = row_or_tile(src, sides[1], lj, out_v, in_v)
    ym = vec8(0.0)
    if lj > 0:
        ym = src[r - 1]
    else:
        ym = row_or_tile(src, sides[2], li * BS + BS - 1, out_v, in_v)
    yp = vec8(0.0)
    if lj < BS - 1:
        yp = src[r + 1]
    else:
        yp = row_or_tile(src, sides[3], li * BS, out_v, in_v)
    zm = row_or_tile(src, sides[4], l, out_v, in_v)[BS - 1]
    zp = row_or_tile(src, sides[5], l, out_v, in_v)[0]
    lo = vec8(zm, own[0], own[1], own[2], own[3], own[4], own[5], own[6])
    hi = vec8(own[1], own[2], own[3], own[4], own[5], own[6], own[7], zp)
    return xm, xp, ym, yp, lo, hi


@wp.kernel
def renormalise_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=vec8),
    out_v: float,
    in_v: float,
    scale: float,
    clip: float,
    far: float,
    out: wp.array(dtype=vec8),
    base: int,
):
    """sparse_kernels.renormalise on the 64 lines along z of one block (thread = block), phi and
    out as vec8 rows (rows): a line's neighbour lines are one load each, the differences vec8
    operations, the gradient's length and the division per voxel as renormalise has them."""
    b = wp.tid() + base
    faces = block_faces(bmap, bcoord[b])
    for l in range(64):
        r = b * 64 + l
        sides = line_sides(faces, l // BS, l - (l // BS) * BS)
        xm, xp, ym, yp, lo, hi = neighbour_rows(phi, sides, r, l, out_v, in_v)
        dx = xp - xm
        dy = yp - ym
        dz = hi - lo
        own = phi[r]
        res = vec8(0.0)
        for z in range(BS):
            grad = 0.5 * wp.length(wp.vec3(dx[z], dy[z], dz[z]))
            v = own[z]
            res[z] = wp.where(wp.abs(v) >= far, wp.where(v > 0.0, clip, -clip), wp.clamp(v / wp.max(grad, 0.05) * scale, -clip, clip))
        out[r] = res


vec27i = wp.types.vector(length=27, dtype=wp.int32)


@wp.kernel
def match_tiles_lines(bcoord: wp.array(dtype=wp.vec3i), bmap: wp.array3d(dtype=wp.int32), phi: wp.array(dtype=float),
                      eps: float, base: int):
    """sparse_kernels.match_tiles on one block (thread = block): the codes of its 26 neighbour
    blocks are looked up once, and a block with no tile among them has nothing to do. The 27
    neighbours of a voxel are visited in match_tiles' order (a voxel next to both kinds of
    tile ends as match_tiles leaves it)."""
    b = wp.tid() + base
    bc = bcoord[b]
    codes = vec27i(0)  # block offset (ox, oy, oz) at (ox + 1) * 9 + (oy + 1) * 3 + oz + 1; itself 0
    tile = int(0)
    for n in range(27):
        if n != 13:
            code = block_code(bmap, wp.vec3i(bc[0] + n // 9 - 1, bc[1] + (n // 3) % 3 - 1, bc[2] + n % 3 - 1))
            codes[n] = code
            if code < 0:
                tile = 1
    if tile == 0:
        return
    for l in range(64):
        li = l // BS
        lj = l - li * BS
        near = int(0)  # a tile among the blocks this line's voxels touch
        # while loops: a range() with run-time bounds costs a step-sign test per iteration
        x0 = wp.where(li == 0, -1, 0)
        x1 = wp.where(li == BS - 1, 2, 1)
        y0 = wp.where(lj == 0, -1, 0)
        y1 = wp.where(lj == BS - 1, 2, 1)
        ox = x0
        while ox < x1:
            oy = y0
            while oy < y1:
                for oz in range(-1, 2):
                    if codes[(ox + 1) * 9 + (oy + 1) * 3 + oz + 1] < 0:
                        near = 1
                oy += 1
            ox += 1
        if near == 0:
            continue
        edge = li == 0 or li == BS - 1 or lj == 0 or lj == BS - 1
        for z in range(BS):
            if edge or z == 0 or z == BS - 1:  # interior voxels have no tile neighbour
                t = (b * 64 + l) * BS + z
                v = phi[t]
                # match_tiles visits the 27 neighbours in (x, y, z) order: the other blocks
                # they fall in come in runs, in lexicographic order of the block offset, and
                # a run's repeats change nothing more, so each block once in that order
                z0 = wp.where(z == 0, -1, 0)
                z1 = wp.where(z == BS - 1, 2, 1)
                bx = x0
                while bx < x1:
                    by = y0
                    while by < y1:
                        bz = z0
                        while bz < z1:
                            if bx != 0 or by != 0 or bz != 0:
                                s = codes[(bx + 1) * 9 + (by + 1) * 3 + bz + 1]
                                if s == TILE_OUTSIDE and v <= 0.0:
                                    v = eps
                                if s == TILE_INSIDE and v > 0.0:
                                    v = -eps
                            bz += 1
                        by += 1
                    bx += 1
                phi[t] = v


@wp.kernel
def project_on_wide_normal_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    wide: wp.array(dtype=float),
    w: wp.array(dtype=float),
    offset: wp.array(dtype=wp.vec3),
    radius_vox: float,
    far_vox: float,
    phi: wp.array(dtype=float),
    base: int,
):
    """sparse_kernels.project_on_wide_normal (isotropic kernels) on one block (thread = block),
    the neighbour blocks looked up once (weight_at: 0 on an OUTSIDE tile, the voxel's own value
    on an INSIDE one)."""
    b = wp.tid() + base
    faces = block_faces(bmap, bcoord[b])
    for l in range(64):
        sides = line_sides(faces, l // BS, l - (l // BS) * BS)
        for z in range(BS):
            t = (b * 64 + l) * BS + z
            if w[t] <= 0.0:
                phi[t] = far_vox
                continue
            n = line_neighbours(wide, sides, t, l, z, 0.0, wide[t])
            g = wp.vec3(n[1] - n[0], n[3] - n[2], n[5] - n[4])
            d = offset[t]
            dist = wp.length(d)
            gl = wp.length(g)
            if gl > 0.0:
                dist = -wp.dot(d, g) / gl  # g points inward (towards the particles)
            phi[t] = dist - radius_vox


@wp.kernel
def limit_inward_lines(bcoord: wp.array(dtype=wp.vec3i), a: wp.array(dtype=vec8), ref: wp.array(dtype=vec8), full: float,
                       gate: wp.array(dtype=float), noise: wp.array(dtype=float), base: int):
    """sparse_kernels.limit_inward for the 64 rows of active block b (thread = block; bcoord
    gives the launch its size), vec8 rows (rows): a = min(a, ref + edge_limit) per voxel, as
    limit_inward (a thread per voxel cost ~2 ns each, 4.4 ms at 2.1 M voxels, one thread)."""
    b = wp.tid() + base
    nb = noise[b]
    for l in range(BS * BS):
        r = b * BS * BS + l
        x = a[r]
        y = ref[r]
        out = vec8(0.0)
        for z in range(BS):
            out[z] = wp.min(x[z], y[z] + edge_limit(full, gate[gate_cell(b, l // BS, l % BS, z)], nb))
        a[r] = out
