"""Warp kernels of the sparse surfacer that work on a line of 8 voxels per thread: the CPU path.

Warp's CPU backend runs a launch's threads one after another on one core, so there what
counts is the work per voxel, not the thread count. The field gather of
:mod:`mpmfx.surface.sparse_kernels` visits each candidate particle once per voxel; here one
thread takes the 8 voxels of a block line along z, visits each candidate particle of the line
once and tests it against the 8 voxels (measured 100k random sphere, CPU: ~3x fewer particle
fetches). Per voxel the same particles are summed in the same order with the same arithmetic,
so the field is the same as the voxel kernel's (tests/surface/test_line_kernels.py).

`base`: the first thread's index, so a launch can be split into chunks run on several CPU
threads (Warp's CPU launches release the GIL; mpmfx.surface.sparse._launch).
"""

import warp as wp

from mpmfx.surface.redistance_kernels import eikonal_update
from mpmfx.surface.sparse_kernels import BS, BV, CS, TILE_INSIDE, TILE_OUTSIDE, line_voxel, slot, stride, write_field

vec8 = wp.types.vector(length=8, dtype=wp.float32)
mat83 = wp.types.matrix(shape=(8, 3), dtype=wp.float32)


@wp.func
def row3(m: mat83, q: int):
    return wp.vec3(m[q, 0], m[q, 1], m[q, 2])


@wp.kernel
def gather_zhu_bridson_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    cells: wp.array3d(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    order: wp.array(dtype=wp.int32),
    g: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    with_v: int,
    reach: float,
    radius_vox: float,
    far_vox: float,
    phi: wp.array(dtype=float),
    w_out: wp.array(dtype=float),
    offset: wp.array(dtype=wp.vec3),
    vel: wp.array(dtype=wp.vec3),
    base: int,
):
    """sparse_kernels.gather_zhu_bridson for the 8 voxels (i, j, k0 .. k0 + 7) of one block line
    (thread = block * 64 + line): the cells within reach of the whole line are visited once."""
    tid = wp.tid() + base
    b = tid // 64
    l = tid - b * 64
    c = bcoord[b] * BS
    i = c[0] + l // BS
    j = c[1] + l % BS
    k0 = c[2]
    r2 = reach * reach
    shape = wp.vec3i(cells.shape[0], cells.shape[1], cells.shape[2])
    lo = wp.vec3i(0)
    hi = wp.vec3i(0)
    ends = wp.vec3(float(i), float(j), float(k0 + BS - 1))
    start = wp.vec3(float(i), float(j), float(k0))
    for a in range(3):
        lo[a] = wp.max(int(wp.floor((start[a] - reach) / float(CS))), 0)
        hi[a] = wp.min(int(wp.floor((ends[a] + reach) / float(CS))), shape[a] - 1)
    w = vec8(0.0)
    dw = mat83(0.0)
    gw = mat83(0.0)
    vw = mat83(0.0)
    for bi in range(lo[0], hi[0] + 1):
        for bj in range(lo[1], hi[1] + 1):
            for bk in range(lo[2], hi[2] + 1):
                cnt = cells[bi, bj, bk]
                if cnt > 0:
                    s = starts[(bi * shape[1] + bj) * shape[2] + bk]
                    for q in range(s, s + cnt):
                        p = order[q]
                        gp = g[p]
                        dx = gp[0] - float(i)
                        dy = gp[1] - float(j)
                        dxy = dx * dx + dy * dy
                        if dxy < r2:
                            for z in range(BS):
                                dz = gp[2] - float(k0 + z)
                                d2 = dxy + dz * dz
                                if d2 < r2:
                                    d = wp.vec3(dx, dy, dz)
                                    u = 1.0 - d2 / r2
                                    wk = u * u * u
                                    w[z] = w[z] + wk
                                    e = wk * d
                                    f = (u * u) * d
                                    for a in range(3):
                                        dw[z, a] = dw[z, a] + e[a]
                                        gw[z, a] = gw[z, a] + f[a]
                                    if with_v != 0:
                                        vp = wk * v[p]
                                        for a in range(3):
                                            vw[z, a] = vw[z, a] + vp[a]
    for z in range(BS):
        write_field(tid * BS + z, w[z], row3(dw, z), row3(gw, z), row3(vw, z), radius_vox, with_v, far_vox, phi, w_out,
                    offset, vel)



@wp.func
def block_code(bmap: wp.array3d(dtype=wp.int32), bc: wp.vec3i):
    """Active index of block bc, or its tile code (OUTSIDE beyond the grid), as `slot` gives."""
    if bc[0] < 0 or bc[1] < 0 or bc[2] < 0 or bc[0] >= bmap.shape[0] or bc[1] >= bmap.shape[1] or bc[2] >= bmap.shape[2]:
        return TILE_OUTSIDE
    return bmap[bc[0], bc[1], bc[2]]


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


@wp.kernel
def blur_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=float),
    axis: int,
    out_v: float,
    in_v: float,
    dst: wp.array(dtype=float),
    base: int,
):
    """sparse_kernels.blur_axis along one block line of `axis` (thread = block * 64 + line)."""
    tid = wp.tid() + base
    b = tid // 64
    lc = line_voxel(axis, 0, tid - b * 64)
    st = stride(axis)
    t0 = b * BV + local_index(lc)
    first = wp.vec3i(lc[0], lc[1], lc[2])
    first[axis] = BS - 1  # the voxel before the line, in the block below
    last = wp.vec3i(lc[0], lc[1], lc[2])  # the voxel after it, in the block above (local 0)
    prev = read(src, side_code(bmap, bcoord[b], axis, -1), local_index(first), out_v, in_v)
    after = read(src, side_code(bmap, bcoord[b], axis, 1), local_index(last), out_v, in_v)
    cur = src[t0]
    for q in range(BS):
        nxt = after
        if q < BS - 1:
            nxt = src[t0 + (q + 1) * st]
        dst[t0 + q * st] = 0.25 * prev + 0.5 * cur + 0.25 * nxt
        prev = cur
        cur = nxt


@wp.kernel
def blur_weight_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=float),
    axis: int,
    step: int,
    dst: wp.array(dtype=float),
    base: int,
):
    """sparse_kernels.blur_weight_axis along one block line of `axis` (1 <= step <= 8): the
    line and the same line of the blocks below and above are read once."""
    tid = wp.tid() + base
    b = tid // 64
    first = local_index(line_voxel(axis, 0, tid - b * 64))
    st = stride(axis)
    below = side_code(bmap, bcoord[b], axis, -1)
    above = side_code(bmap, bcoord[b], axis, 1)
    cur = vec8(0.0)
    lo = vec8(0.0)
    hi = vec8(0.0)
    for q in range(BS):
        cur[q] = src[b * BV + first + q * st]
        if below >= 0:
            lo[q] = src[below * BV + first + q * st]
        if above >= 0:
            hi[q] = src[above * BV + first + q * st]
    for q in range(BS):
        own = cur[q]
        a = float(0.0)  # weight_at: 0 on an OUTSIDE tile, the voxel's own value on an INSIDE one
        if q >= step:
            a = cur[q - step]
        elif below >= 0:
            a = lo[q - step + BS]
        elif below == TILE_INSIDE:
            a = own
        c = float(0.0)
        if q + step < BS:
            c = cur[q + step]
        elif above >= 0:
            c = hi[q + step - BS]
        elif above == TILE_INSIDE:
            c = own
        dst[b * BV + first + q * st] = 0.25 * a + 0.5 * own + 0.25 * c


vec6 = wp.types.vector(length=6, dtype=wp.float32)
vec6i = wp.types.vector(length=6, dtype=wp.int32)


@wp.func
def line_sides(bmap: wp.array3d(dtype=wp.int32), bc: wp.vec3i, li: int, lj: int):
    """Codes of the blocks holding the -x, +x, -y, +y, -z, +z neighbours of line (li, lj) of
    block bc that lie outside it (OUTSIDE where the line is not at that face)."""
    c = vec6i(TILE_OUTSIDE)
    if li == 0:
        c[0] = side_code(bmap, bc, 0, -1)
    if li == BS - 1:
        c[1] = side_code(bmap, bc, 0, 1)
    if lj == 0:
        c[2] = side_code(bmap, bc, 1, -1)
    if lj == BS - 1:
        c[3] = side_code(bmap, bc, 1, 1)
    c[4] = side_code(bmap, bc, 2, -1)
    c[5] = side_code(bmap, bc, 2, 1)
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


@wp.kernel
def renormalise_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    scale: float,
    clip: float,
    out: wp.array(dtype=float),
    base: int,
):
    """sparse_kernels.renormalise on the 8 voxels of one block line along z."""
    tid = wp.tid() + base
    b = tid // 64
    l = tid - b * 64
    sides = line_sides(bmap, bcoord[b], l // BS, l - (l // BS) * BS)
    for z in range(BS):
        t = tid * BS + z
        n = line_neighbours(phi, sides, t, l, z, out_v, in_v)
        grad = 0.5 * wp.length(wp.vec3(n[1] - n[0], n[3] - n[2], n[5] - n[4]))
        out[t] = wp.clamp(phi[t] / wp.max(grad, 0.05) * scale, -clip, clip)


@wp.kernel
def eikonal_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=float),
    frozen: wp.array(dtype=wp.int32),
    out_v: float,
    in_v: float,
    clip: float,
    dst: wp.array(dtype=float),
    was: wp.array(dtype=wp.int32),
    first: int,
    now: wp.array(dtype=wp.int32),
    base: int,
):
    """redistance_kernels.eikonal_sweep on the 8 voxels of one block line along z.

    was / now: per line, 1 where the previous / this sweep changed a value. A line whose
    neighbour lines (the 6 it reads) and itself did not change in the previous sweep would
    compute what it holds, and with src and dst swapped every sweep dst holds the values of two
    sweeps ago, the same ones: it is skipped (first != 0: the first sweep, nothing skipped).
    Only the lines at the moving front work, and the result is the plain Jacobi sweep's."""
    tid = wp.tid() + base
    b = tid // 64
    l = tid - b * 64
    li = l // BS
    lj = l - li * BS
    sides = line_sides(bmap, bcoord[b], li, lj)
    if first == 0:
        busy = was[tid] + line_flag(was, sides[0], (BS - 1) * BS + lj) + line_flag(was, sides[1], lj)
        busy += line_flag(was, sides[2], li * BS + BS - 1) + line_flag(was, sides[3], li * BS)
        busy += line_flag(was, sides[4], l) + line_flag(was, sides[5], l)
        if li > 0:
            busy += was[tid - BS]
        if li < BS - 1:
            busy += was[tid + BS]
        if lj > 0:
            busy += was[tid - 1]
        if lj < BS - 1:
            busy += was[tid + 1]
        if busy == 0:
            now[tid] = 0
            return
    moved = int(0)
    t0 = tid * BS
    for z in range(BS):
        t = t0 + z
        v = src[t]
        if frozen[t] != 0:
            dst[t] = v
            continue
        n = line_neighbours(src, sides, t, l, z, out_v, in_v)
        a = wp.vec3(wp.min(wp.abs(n[0]), wp.abs(n[1])), wp.min(wp.abs(n[2]), wp.abs(n[3])), wp.min(wp.abs(n[4]), wp.abs(n[5])))
        u = eikonal_update(a, v, clip)
        dst[t] = u
        if u != v:
            moved = 1
    now[tid] = moved


@wp.func
def line_flag(flags: wp.array(dtype=wp.int32), code: int, line: int):
    """flags of line `line` (0..63) of the block with code `code`; 0 for a tile."""
    if code >= 0:
        return flags[code * 64 + line]
    return 0


vec8i = wp.types.vector(length=8, dtype=wp.int32)


@wp.func
def corner_blocks(bmap: wp.array3d(dtype=wp.int32), b: int, bc: wp.vec3i):
    """Codes of block bc (index 0, active index b) and its 7 upper neighbours: index
    ox * 4 + oy * 2 + oz for the block bc + (ox, oy, oz), as block_code gives them."""
    codes = vec8i(0)
    for n in range(8):
        if n == 0:
            codes[n] = b
        else:
            codes[n] = block_code(bmap, wp.vec3i(bc[0] + n // 4, bc[1] + (n // 2) % 2, bc[2] + n % 2))
    return codes


@wp.func
def corner_get(phi: wp.array(dtype=float), codes: vec8i, x: int, y: int, z: int, out_v: float, in_v: float):
    """`get` of the voxel at local (x, y, z) of the block of codes[0], each in 0..8."""
    ox = x // BS
    oy = y // BS
    oz = z // BS
    return read(phi, codes[ox * 4 + oy * 2 + oz], local_index(wp.vec3i(x - ox * BS, y - oy * BS, z - oz * BS)), out_v,
                in_v)


@wp.kernel
def mc_vertices_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    offsets: wp.array(dtype=wp.int32),
    count_only: int,
    counts: wp.array(dtype=wp.int32),
    edge_vert: wp.array(dtype=wp.int32),
    verts: wp.array(dtype=wp.vec3),
    base: int,
):
    """sparse_mesh_kernels.mc_vertices for the 24 edges (voxel * 3 + axis) of one block line
    along z, counted per line (counts[line]; offsets: their inclusive scan): the same vertices
    in the same order."""
    tid = wp.tid() + base
    b = tid // 64
    l = tid - b * 64
    li = l // BS
    lj = l - li * BS
    bc = bcoord[b]
    codes = corner_blocks(bmap, b, bc)
    idx = int(0)
    if count_only == 0:
        idx = offsets[tid] - counts[tid]
    n = int(0)
    for z in range(BS):
        t = tid * BS + z
        a = phi[t]
        for axis in range(3):
            o = wp.vec3i(0)
            o[axis] = 1
            v = corner_get(phi, codes, li + o[0], lj + o[1], z + o[2], out_v, in_v)
            e = t * 3 + axis
            if (a >= 0.0) != (v >= 0.0):
                n += 1
                if count_only == 0:
                    edge_vert[e] = idx
                    p = wp.vec3(float(bc[0] * BS + li), float(bc[1] * BS + lj), float(bc[2] * BS + z))
                    p[axis] = p[axis] + wp.clamp(a / (a - v), 0.0, 1.0)
                    verts[idx] = p
                    idx += 1
            elif count_only == 0:
                edge_vert[e] = -1
    if count_only != 0:
        counts[tid] = n


@wp.kernel
def mc_faces_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    edge_vert: wp.array(dtype=wp.int32),
    tri_range: wp.array(dtype=wp.int32),
    tri_local: wp.array(dtype=wp.int32),
    edge_offset: wp.array2d(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    count_only: int,
    counts: wp.array(dtype=wp.int32),
    faces: wp.array(dtype=wp.int32),
    base: int,
):
    """sparse_mesh_kernels.mc_faces for the 8 cells of one block line along z, counted per
    line: the same triangles in the same order."""
    tid = wp.tid() + base
    b = tid // 64
    l = tid - b * 64
    li = l // BS
    lj = l - li * BS
    bc = bcoord[b]
    codes = corner_blocks(bmap, b, bc)
    first = int(0)
    if count_only == 0:
        first = offsets[tid] - counts[tid]
    total = int(0)
    for z in range(BS):
        code = int(0)
        for n in range(8):
            # corner order of warp.geometry: (0,0,0) (1,0,0) (1,1,0) (0,1,0), then z + 1
            q = n % 4
            dx = wp.where(q == 1 or q == 2, 1, 0)
            dy = wp.where(q >= 2, 1, 0)
            if corner_get(phi, codes, li + dx, lj + dy, z + n // 4, out_v, in_v) >= 0.0:
                code += 1 << n
        start = tri_range[code]
        ntri = (tri_range[code + 1] - start) // 3
        if count_only == 0:
            c = wp.vec3i(bc[0] * BS + li, bc[1] * BS + lj, bc[2] * BS + z)
            for m in range(ntri):
                for s in range(3):
                    le = tri_local[start + 3 * m + s]
                    sl = slot(bmap, c[0] + edge_offset[le, 0], c[1] + edge_offset[le, 1], c[2] + edge_offset[le, 2])
                    idx = int(-1)
                    if sl >= 0:
                        idx = edge_vert[sl * 3 + edge_offset[le, 3]]
                    faces[3 * (first + total + m) + s] = idx
        total += ntri
    if count_only != 0:
        counts[tid] = total
