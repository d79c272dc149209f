"""Marching cubes a block per thread (its 64 lines along z in turn): the CPU path of :mod:`mpmfx.surface.sparse_mesh_kernels`.

A line along z of block b owns the 24 edges (voxel * 3 + axis) and the 8 cells (lower corner)
of its voxels. Each needs the values of at most 4 voxel columns (the line and its +x, +y, +xy
neighbours, up to z + 8), so these are read once per line (36 reads instead of 64 per cell
sweep) and their signs kept as 9-bit masks: counting is bit arithmetic, and a line whose
columns all share one sign has nothing to do. The signs are found once per line
(sign_columns: a line's 8 voxels and the next one along z as a 9-bit mask), so the count
passes and the triangles read one int per column instead of its 9 values. The same vertices
and triangles come out in the same order as the voxel kernels' (tests/surface/test_line_kernels.py).
"""

import warp as wp

from mpmfx.surface.line_kernels import block_code, read, row_or_tile, side_code, vec8
from mpmfx.surface.sparse_kernels import BS, BV, TILE_INSIDE

vec9 = wp.types.vector(length=9, dtype=wp.float32)
vec8i = wp.types.vector(length=8, dtype=wp.int32)
ALL = wp.constant(511)  # 9 sign bits set


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
def column(phi: wp.array(dtype=float), codes: vec8i, x: int, y: int, out_v: float, in_v: float):
    """Values at local (x, y, z), z = 0..8, of the block of codes[0] (x, y in 0..8)."""
    ox = x // BS
    oy = y // BS
    lxy = ((x - ox * BS) * BS + (y - oy * BS)) * BS
    lo = codes[ox * 4 + oy * 2]
    col = vec9(0.0)
    if lo >= 0:
        for z in range(BS):
            col[z] = phi[lo * 512 + lxy + z]
    else:
        for z in range(BS):
            col[z] = read(phi, lo, 0, out_v, in_v)
    col[BS] = read(phi, codes[ox * 4 + oy * 2 + 1], lxy, out_v, in_v)
    return col


@wp.kernel
def sign_columns(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi8: wp.array(dtype=vec8),
    out_v: float,
    in_v: float,
    masks: wp.array(dtype=wp.int32),
    base: int,
):
    """masks[line] = the corner signs of the line's column: bit z (0..7) where its voxel z is
    >= 0, bit 8 where the first voxel of the same line of the block above along z is (a
    tile's value there). phi8: the values as vec8 rows along z (line_kernels.rows); thread = block."""
    b = wp.tid() + base
    zp = side_code(bmap, bcoord[b], 2, 1)
    for l in range(64):
        row = phi8[b * 64 + l]
        m = int(0)
        for z in range(BS):
            m = m | wp.where(row[z] >= 0.0, 1 << z, 0)
        top = row_or_tile(phi8, zp, l, out_v, in_v)[0]
        masks[b * 64 + l] = m | wp.where(top >= 0.0, 1 << BS, 0)


@wp.func
def column_mask(masks: wp.array(dtype=wp.int32), codes: vec8i, x: int, y: int, out_v: float, in_v: float):
    """Bit z set where column(...)[z] >= 0 (the corner sign marching cubes uses), local
    (x, y, z), z = 0..8, of the block of codes[0] (x, y in 0..8), from sign_columns' masks."""
    ox = x // BS
    oy = y // BS
    line = (x - ox * BS) * BS + (y - oy * BS)
    lo = codes[ox * 4 + oy * 2]
    if lo >= 0:
        return masks[lo * 64 + line]
    # a tile's 8 voxels hold its value (read); the ninth is the block above's
    m = wp.where(wp.where(lo == TILE_INSIDE, in_v, out_v) >= 0.0, (1 << BS) - 1, 0)
    hi = codes[ox * 4 + oy * 2 + 1]
    top = int(0)
    if hi >= 0:
        top = masks[hi * 64 + line] & 1
    else:
        top = wp.where(wp.where(hi == TILE_INSIDE, in_v, out_v) >= 0.0, 1, 0)
    return m | (top << BS)


@wp.func
def edge_bits(ex: int, ey: int, ez: int):
    """The crossing edges of a line as one mask in mc_vertices' order: bit z * 3 + axis for
    edge (voxel z, axis), from the masks of its x, y and z edges (bit z each)."""
    m = int(0)
    for z in range(BS):
        m = m | (((ex >> z) & 1) << (3 * z)) | (((ey >> z) & 1) << (3 * z + 1)) | (((ez >> z) & 1) << (3 * z + 2))
    return m


@wp.kernel
def mc_vertices_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    masks: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    count_only: int,
    counts: wp.array(dtype=wp.int32),
    edge_vert: wp.array(dtype=wp.int32),
    verts: wp.array(dtype=wp.vec3),
    base: int,
):
    """sparse_mesh_kernels.mc_vertices for the 24 edges (voxel * 3 + axis) of each of the 64
    lines along z of one block (thread = block), counted per line (counts[line]; offsets:
    their inclusive scan): the same vertices in the same order. Unlike mc_vertices, edges
    without a vertex keep whatever edge_vert held: mc_faces_lines reads only crossing edges.
    masks: sign_columns of phi (the count pass reads only those)."""
    b = wp.tid() + base
    bc = bcoord[b]
    codes = corner_blocks(bmap, b, bc)
    for l in range(64):
        tid = b * 64 + l
        if count_only == 0 and counts[tid] == 0:
            continue  # no vertex (and edge_vert is read only at crossing edges: no -1 to write)
        li = l // BS
        lj = l - li * BS
        m0 = masks[tid]
        low = (1 << BS) - 1
        ex = (m0 ^ column_mask(masks, codes, li + 1, lj, out_v, in_v)) & low  # bit z: edge (voxel z, axis 0) crosses
        ey = (m0 ^ column_mask(masks, codes, li, lj + 1, out_v, in_v)) & low
        ez = (m0 ^ (m0 >> 1)) & low
        if count_only != 0:
            counts[tid] = wp.bit_count(ex) + wp.bit_count(ey) + wp.bit_count(ez)  # popcnt (a loop over 9 bits each: 10 -> 3 ms)
            continue
        own = column(phi, codes, li, lj, out_v, in_v)  # the values, at the lines with a vertex
        cx = column(phi, codes, li + 1, lj, out_v, in_v)
        cy = column(phi, codes, li, lj + 1, out_v, in_v)
        idx = offsets[tid] - counts[tid]
        # the crossing edges in mc_vertices' order (voxel z, then axis), the next one the lowest
        # set bit: a branch per edge on whether it crosses mispredicted
        hits = edge_bits(ex, ey, ez)
        while hits != 0:
            e = wp.bit_count((hits & (-hits)) - 1)
            hits = hits & (hits - 1)
            z = e // 3
            axis = e - 3 * z
            a = own[z]
            v = wp.where(axis == 0, cx[z], wp.where(axis == 1, cy[z], own[z + 1]))
            edge_vert[(tid * BS + z) * 3 + axis] = idx
            p = wp.vec3(float(bc[0] * BS + li), float(bc[1] * BS + lj), float(bc[2] * BS + z))
            p[axis] = p[axis] + wp.clamp(a / (a - v), 0.0, 1.0)
            verts[idx] = p
            idx += 1


@wp.kernel
def mc_faces_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    masks: wp.array(dtype=wp.int32),
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
    """sparse_mesh_kernels.mc_faces for the 8 cells of each of the 64 lines along z of one
    block (thread = block), counted per line: the same triangles in the same order. Only the
    corner signs count: masks from sign_columns (out_v, in_v: the tiles' values)."""
    b = wp.tid() + base
    bc = bcoord[b]
    codes = corner_blocks(bmap, b, bc)
    for l in range(64):
        tid = b * 64 + l
        if count_only == 0 and counts[tid] == 0:
            continue
        li = l // BS
        lj = l - li * BS
        # corner order of warp.geometry: (0,0,0) (1,0,0) (1,1,0) (0,1,0), then z + 1
        m0 = masks[tid]
        m1 = column_mask(masks, codes, li + 1, lj, out_v, in_v)
        m2 = column_mask(masks, codes, li + 1, lj + 1, out_v, in_v)
        m3 = column_mask(masks, codes, li, lj + 1, out_v, in_v)
        if (m0 & m1 & m2 & m3) == ALL or (m0 | m1 | m2 | m3) == 0:  # one sign: no triangle
            counts[tid] = 0  # (count pass; the write pass skipped the line above)
            continue
        first = int(0)
        if count_only == 0:
            first = offsets[tid] - counts[tid]
        total = int(0)
        for z in range(BS):
            lowz = ((m0 >> z) & 1) | (((m1 >> z) & 1) << 1) | (((m2 >> z) & 1) << 2) | (((m3 >> z) & 1) << 3)
            z1 = z + 1
            code = lowz | (((m0 >> z1) & 1) << 4) | (((m1 >> z1) & 1) << 5) | (((m2 >> z1) & 1) << 6) | (((m3 >> z1) & 1) << 7)
            start = tri_range[code]
            ntri = (tri_range[code + 1] - start) // 3
            if count_only == 0:
                m = int(0)
                while m < ntri:  # not range(): a run-time bound costs a step-sign test per iteration
                    for s in range(3):
                        le = tri_local[start + 3 * m + s]
                        # the edge's voxel lies in this block or one of its 7 upper neighbours:
                        # its block from `codes`, as slot() finds it through the block grid (the
                        # two passes alone, one thread, best of 15: lattice fine sphere / torus /
                        # box 9.3 / 15.1 / 7.5 -> 8.6 / 13.1 / 6.5 ms, the same faces)
                        lx = li + edge_offset[le, 0]
                        ly = lj + edge_offset[le, 1]
                        lz = z + edge_offset[le, 2]
                        ox = lx >> 3
                        oy = ly >> 3
                        oz = lz >> 3
                        code = codes[ox * 4 + oy * 2 + oz]
                        idx = int(-1)
                        if code >= 0:
                            idx = edge_vert[(code * BV + ((lx - ox * BS) * BS + (ly - oy * BS)) * BS + (lz - oz * BS)) * 3 + edge_offset[le, 3]]
                        faces[3 * (first + total + m) + s] = idx
                    m += 1
            total += ntri
        if count_only != 0:
            counts[tid] = total
