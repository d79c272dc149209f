"""The Warp functions of the sparse surfacer's CPU variants: a block of 8^3 voxels per thread,
worked through as 64 lines of 8 voxels along z.

Warp's CPU backend runs a launch's threads one after another on one core, so there what
counts is the work per voxel, not the thread count: the GPU's layout (a thread per voxel) pays
there for what a GPU hides (index arithmetic, a block-map lookup per neighbour read). Here the
neighbour blocks are looked up once per block and a line's neighbour lines are read once.
Every voxel gets the same arithmetic in the same order as in the voxel kernels, so the results
are theirs bit for bit (tests/surface/test_line_kernels.py).

`base` (every CPU kernel's last argument): the first thread's index, so a launch can be split
into chunks run on several CPU threads (Warp's CPU launches release the GIL; :mod:`mpmfx.surface.launch`).
"""

import warp as wp

from mpmfx.surface.voxels import BS, BV, TILE_INSIDE, TILE_OUTSIDE
from mpmfx.surface.voxels import block_tile as block_code

vec8 = wp.types.vector(length=8, dtype=wp.float32)


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


def rows(a):
    """A vec8 view of the float array a (voxels, a block's 512 in order): its rows of 8 voxels
    along z, the same memory (the caller keeps a alive)."""
    return wp.array(ptr=a.ptr, shape=(a.shape[0] // BS,), dtype=vec8, device=a.device)


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
