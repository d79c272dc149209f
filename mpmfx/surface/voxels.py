"""The sparse surfacer's block layout and the Warp functions its voxel kernels share.

The grid is cut into blocks of 8^3 voxels (an OpenVDB leaf). `bmap[bi, bj, bk]` holds the
index of an active block (>= 0) or a constant tile: OUTSIDE (-1) or INSIDE (-2). Voxel data of
active block b live at `data[b * 512 + (li * 8 + lj) * 8 + lk]`. Voxel (i, j, k) sits at grid
coordinates (i, j, k), i.e. world `origin + (i, j, k) * voxel`.

A pass's GPU variant takes a voxel (or a line of 8 voxels) per thread; its CPU variant a block
per thread (:mod:`mpmfx.surface.lines`). Both give every voxel the same arithmetic in the same
order, so their results agree bit for bit (tests/surface/test_line_kernels.py).
"""

import warp as wp

BS = wp.constant(8)  # block edge in voxels

CS = wp.constant(4)  # edge of the cells particles are binned in for the field gather, voxels

BV = wp.constant(512)  # voxels per block

TILE_OUTSIDE = wp.constant(-1)

TILE_INSIDE = wp.constant(-2)

TILE_ACTIVE = wp.constant(-3)  # before compaction

LABEL_NONE = wp.constant(-1)

LABEL_BIG = wp.constant(2147483647)


@wp.func
def voxel_of(tid: int, bcoord: wp.array(dtype=wp.vec3i)):
    """Global voxel index of thread `tid` over active voxels."""
    b = tid // BV
    l = tid - b * BV
    c = bcoord[b] * BS
    return wp.vec3i(c[0] + l // 64, c[1] + (l // 8) % 8, c[2] + l % 8)


@wp.func
def slot(bmap: wp.array3d(dtype=wp.int32), i: int, j: int, k: int):
    """Data index of voxel (i, j, k), or TILE_OUTSIDE / TILE_INSIDE for constant tiles."""
    if i < 0 or j < 0 or k < 0:
        return TILE_OUTSIDE
    bi = i // BS
    bj = j // BS
    bk = k // BS
    if bi >= bmap.shape[0] or bj >= bmap.shape[1] or bk >= bmap.shape[2]:
        return TILE_OUTSIDE
    b = bmap[bi, bj, bk]
    if b < 0:
        return b
    return b * BV + ((i - bi * BS) * BS + (j - bj * BS)) * BS + (k - bk * BS)


@wp.func
def get(
    bmap: wp.array3d(dtype=wp.int32), data: wp.array(dtype=float), i: int, j: int, k: int, out_v: float, in_v: float
):
    s = slot(bmap, i, j, k)
    if s >= 0:
        return data[s]
    if s == TILE_INSIDE:
        return in_v
    return out_v


@wp.func
def stride(axis: int):
    """Data-index step of one voxel along `axis` inside a block."""
    return wp.where(axis == 0, BS * BS, wp.where(axis == 1, BS, 1))


@wp.func
def step_get(
    bmap: wp.array3d(dtype=wp.int32),
    data: wp.array(dtype=float),
    t: int,
    c: wp.vec3i,
    axis: int,
    sgn: int,
    out_v: float,
    in_v: float,
):
    """`get` of the voxel c + sgn along `axis` (sgn = +-1), c being active voxel t: most
    neighbours lie in the same block, read directly (no block-map lookup)."""
    l = c[axis] % BS  # voxel indices are >= 0
    if (sgn > 0 and l < BS - 1) or (sgn < 0 and l > 0):
        return data[t + sgn * stride(axis)]
    o = wp.vec3i(0)
    o[axis] = sgn
    return get(bmap, data, c[0] + o[0], c[1] + o[1], c[2] + o[2], out_v, in_v)


@wp.func
def block_tile(bmap: wp.array3d(dtype=wp.int32), bc: wp.vec3i):
    """Active index of block bc, or its tile code (TILE_OUTSIDE beyond the grid), as `slot`."""
    if (
        bc[0] < 0
        or bc[1] < 0
        or bc[2] < 0
        or bc[0] >= bmap.shape[0]
        or bc[1] >= bmap.shape[1]
        or bc[2] >= bmap.shape[2]
    ):
        return TILE_OUTSIDE
    return bmap[bc[0], bc[1], bc[2]]


@wp.func
def side_line(bmap: wp.array3d(dtype=wp.int32), bc: wp.vec3i, b: int, x: int, y: int, dz: int):
    """First data index of the z line (x, y) (each -1..BS) of the block dz (-1, 0, 1) blocks along
    z from active block b (bc its coordinates), x or y outside 0..BS-1 meaning that line of the
    block next to it along x or y; or that block's tile code (-1 OUTSIDE, -2 INSIDE, beyond the
    grid OUTSIDE) shifted below -BV, so any index >= 0 is data (line_value reads both)."""
    bx = wp.where(x < 0, -1, wp.where(x >= BS, 1, 0))
    by = wp.where(y < 0, -1, wp.where(y >= BS, 1, 0))
    if bx == 0 and by == 0 and dz == 0:
        return b * BV + (x * BS + y) * BS
    code = block_tile(bmap, wp.vec3i(bc[0] + bx, bc[1] + by, bc[2] + dz))
    if code < 0:
        return code - BV
    return code * BV + ((x - bx * BS) * BS + (y - by * BS)) * BS


@wp.func
def line_value(src: wp.array(dtype=float), line: int, k: int, out_v: float, in_v: float):
    """Voxel k (0..BS-1) of a line side_line gave, or its tile's value (as `get`)."""
    if line >= 0:
        return src[line + k]
    return wp.where(line + BV == TILE_INSIDE, in_v, out_v)


@wp.func
def line_z(src: wp.array(dtype=float), line: int, below: int, above: int, k: int, out_v: float, in_v: float):
    """Voxel k (-1..BS) of a z line, given the line and the same line in the blocks below and
    above (side_line with dz = 0, -1, 1)."""
    if k < 0:
        return line_value(src, below, BS - 1, out_v, in_v)
    if k >= BS:
        return line_value(src, above, 0, out_v, in_v)
    return line_value(src, line, k, out_v, in_v)


@wp.func
def interior(c: wp.vec3i):
    """True when all 26 neighbours of voxel c lie in its own block."""
    ok = True
    for a in range(3):
        l = c[a] % BS
        if l == 0 or l == BS - 1:
            ok = False
    return ok


@wp.func
def in_block(c: wp.vec3i, o: wp.vec3i):
    """True when voxel c + o lies in voxel c's block."""
    ok = True
    for a in range(3):
        l = c[a] % BS + o[a]
        if l < 0 or l >= BS:
            ok = False
    return ok


@wp.func
def line_voxel(axis: int, s: int, l: int):
    """Local coordinates of step s along `axis` of line l (0..63) of a block."""
    c = wp.vec3i(0)
    u = l // BS
    w = l - u * BS
    if axis == 0:
        c = wp.vec3i(s, u, w)
    elif axis == 1:
        c = wp.vec3i(u, s, w)
    else:
        c = wp.vec3i(u, w, s)
    return c


@wp.func
def line_start(axis: int, l: int):
    """(index within its block of line l's first voxel along `axis`, the index step along it)."""
    c = line_voxel(axis, 0, l)
    return (c[0] * BS + c[1]) * BS + c[2], stride(axis)


@wp.func
def weight_at(bmap: wp.array3d(dtype=wp.int32), w: wp.array(dtype=float), t: int, i: int, j: int, k: int):
    """Kernel weight sum at voxel (i, j, k): 0 on OUTSIDE tiles (no particle within reach), and
    voxel t's own value on INSIDE tiles (the bulk, where the field is flat anyway)."""
    s = slot(bmap, i, j, k)
    if s >= 0:
        return w[s]
    if s == TILE_INSIDE:
        return w[t]
    return 0.0


@wp.func
def gate_cell(b: int, i: int, j: int, k: int):
    """Index of the 2^3-voxel cell (edges.edge_gate) of voxel (i, j, k) of active block b."""
    return b * 64 + (i // 2) * 16 + (j // 2) * 4 + k // 2
