"""Mesh pass: marching cubes over the active cells (Warp's tables,
:mod:`mpmfx.surface.mc_tables`), vertex normals and velocities; and before it, the tile signs
(match_tiles: marching cubes needs no crossing on a tile face).

GPU: a thread per edge and per cell. CPU: a block per thread, its 64 lines along z in turn. A
line owns the 24 edges (voxel * 3 + axis) and the 8 cells (lower corner) of its voxels. Each
needs the values of at most 4 voxel columns (the line and its +x, +y, +xy neighbours, up to
z + 8), so these are read once per line and their signs kept as 9-bit masks (sign_columns):
counting is bit arithmetic, and a line whose columns all share one sign has nothing to do. The
same vertices and triangles come out in the same order as the voxel kernels'
(tests/surface/test_line_kernels.py).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from mpmfx.surface.grid import SparseGrid
from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import launch_blocks, scan, split
from mpmfx.surface.lines import read, row_or_tile, rows, side_code, vec8, vec27i
from mpmfx.surface.mc_tables import device_tables
from mpmfx.surface.voxels import BS, BV, TILE_INSIDE, TILE_OUTSIDE, block_tile, get, interior, slot, step_get, voxel_of
from mpmfx.surface.voxels import block_tile as block_code

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


@wp.kernel
def match_tiles(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    eps: float,
    base: int,
):
    """Give voxels next to a constant tile that tile's sign, so no zero crossing touches a tile
    (marching cubes runs only on cells whose lower corner is active).

    The 26 neighbours of a voxel on its block's boundary fall in at most 7 other blocks, each
    looked up once, in lexicographic order of the block offset: visiting the neighbours one by
    one in (x, y, z) order meets the same blocks in that order, and a block met again changes
    nothing more."""
    t = wp.tid() + base
    c = voxel_of(t, bcoord)
    if interior(c):
        return
    bc = bcoord[t // BV]
    lo = wp.vec3i(0)
    hi = wp.vec3i(1)
    for a in range(3):
        l = c[a] % BS
        lo[a] = wp.where(l == 0, -1, 0)
        hi[a] = wp.where(l == BS - 1, 2, 1)
    v = phi[t]
    for bx in range(lo[0], hi[0]):
        for by in range(lo[1], hi[1]):
            for bz in range(lo[2], hi[2]):
                if bx != 0 or by != 0 or bz != 0:
                    s = block_tile(bmap, wp.vec3i(bc[0] + bx, bc[1] + by, bc[2] + bz))
                    if s == TILE_OUTSIDE and v <= 0.0:
                        v = eps
                    if s == TILE_INSIDE and v > 0.0:
                        v = -eps
    phi[t] = v


@cpu_kernel
def match_tiles_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    eps: float,
    base: int,
):
    """match_tiles on one block (thread = block): the codes of its 26 neighbour
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
def mc_vertices(
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
    """One thread per (active voxel, axis), e = voxel * 3 + axis: a vertex where phi changes
    sign along the edge."""
    e = wp.tid() + base
    t = e // 3
    axis = e - t * 3
    c = voxel_of(t, bcoord)
    a = phi[t]
    b = step_get(bmap, phi, t, c, axis, 1, out_v, in_v)
    crossing = (a >= 0.0) != (b >= 0.0)
    if count_only != 0:
        counts[e] = wp.where(crossing, 1, 0)
        return
    if not crossing:
        edge_vert[e] = -1
        return
    f = wp.clamp(a / (a - b), 0.0, 1.0)
    idx = offsets[e] - 1  # inclusive scan
    edge_vert[e] = idx
    p = wp.vec3(float(c[0]), float(c[1]), float(c[2]))
    p[axis] = p[axis] + f
    verts[idx] = p


@wp.kernel
def mc_faces(
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
    """Triangles of the cell whose lower corner is active voxel t (warp.geometry's tables)."""
    t = wp.tid() + base
    c = voxel_of(t, bcoord)
    inner = c[0] % BS < BS - 1 and c[1] % BS < BS - 1 and c[2] % BS < BS - 1  # all 8 corners in t's block
    code = int(0)
    for n in range(8):
        # corner order of warp.geometry: (0,0,0) (1,0,0) (1,1,0) (0,1,0), then z + 1
        q = n % 4
        dx = wp.where(q == 1 or q == 2, 1, 0)
        dy = wp.where(q >= 2, 1, 0)
        dz = n // 4
        val = float(0.0)
        if inner:
            val = phi[t + (dx * BS + dy) * BS + dz]
        else:
            val = get(bmap, phi, c[0] + dx, c[1] + dy, c[2] + dz, out_v, in_v)
        if val >= 0.0:
            code += 1 << n
    start = tri_range[code]
    ntri = (tri_range[code + 1] - start) // 3
    if count_only != 0:
        counts[t] = ntri
        return
    if ntri == 0:
        return
    first = offsets[t] - ntri  # inclusive scan
    for m in range(ntri):
        for s in range(3):
            le = tri_local[start + 3 * m + s]
            sl = slot(bmap, c[0] + edge_offset[le, 0], c[1] + edge_offset[le, 1], c[2] + edge_offset[le, 2])
            idx = int(-1)
            if sl >= 0:
                idx = edge_vert[sl * 3 + edge_offset[le, 3]]
            faces[3 * (first + m) + s] = idx


@wp.kernel
def sample_vertices(
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    vel: wp.array(dtype=wp.vec3),
    wsum: wp.array(dtype=float),
    with_v: int,
    verts: wp.array(dtype=wp.vec3),
    origin: wp.vec3,
    voxel: float,
    world: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    base: int,
):
    """World position, outward normal (trilinear gradient) and trilinear velocity per vertex.

    The velocity interpolates only the corners that some particle reaches (kernel weight sum
    wsum > 0; the others hold no velocity), renormalised: where the closing filled a sample void
    (SurfaceParams.close_voids) a vertex can lie next to voxels no particle reaches, and reading
    them as 0 slowed such vertices (0.68 of the particles' speed at worst, 3000 random particles)."""
    t = wp.tid() + base
    g = verts[t]
    c = wp.vec3i(int(wp.floor(g[0])), int(wp.floor(g[1])), int(wp.floor(g[2])))
    f = g - wp.vec3(float(c[0]), float(c[1]), float(c[2]))
    grad = wp.vec3(0.0)
    vv = wp.vec3(0.0)
    vw = float(0.0)
    for n in range(8):
        ox = n & 1
        oy = (n >> 1) & 1
        oz = (n >> 2) & 1
        wx = wp.where(ox == 1, f[0], 1.0 - f[0])
        wy = wp.where(oy == 1, f[1], 1.0 - f[1])
        wz = wp.where(oz == 1, f[2], 1.0 - f[2])
        val = get(bmap, phi, c[0] + ox, c[1] + oy, c[2] + oz, out_v, in_v)
        sx = wp.where(ox == 1, 1.0, -1.0)
        sy = wp.where(oy == 1, 1.0, -1.0)
        sz = wp.where(oz == 1, 1.0, -1.0)
        grad += val * wp.vec3(sx * wy * wz, sy * wx * wz, sz * wx * wy)
        if with_v != 0:
            s = slot(bmap, c[0] + ox, c[1] + oy, c[2] + oz)
            if s >= 0:
                if wsum[s] > 0.0:
                    vv += (wx * wy * wz) * vel[s]
                    vw += wx * wy * wz
    ln = wp.length(grad)
    normals[t] = wp.where(ln > 0.0, grad / wp.max(ln, 1.0e-20), wp.vec3(0.0, 0.0, 1.0))
    velocities[t] = wp.where(vw > 0.0, vv / wp.max(vw, 1.0e-20), wp.vec3(0.0))
    world[t] = origin + g * voxel


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


@cpu_kernel
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
    tile's value there). phi8: the values as vec8 rows along z (lines.rows); thread = block."""
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


@cpu_kernel
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
    """mc_vertices for the 24 edges (voxel * 3 + axis) of each of the 64
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
            counts[tid] = wp.bit_count(ex) + wp.bit_count(ey) + wp.bit_count(ez)  # popcnt (not a loop over 9 bits each)
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


@cpu_kernel
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
    """mc_faces for the 8 cells of each of the 64 lines along z of one
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
            code = (
                lowz
                | (((m0 >> z1) & 1) << 4)
                | (((m1 >> z1) & 1) << 5)
                | (((m2 >> z1) & 1) << 6)
                | (((m3 >> z1) & 1) << 7)
            )
            start = tri_range[code]
            ntri = (tri_range[code + 1] - start) // 3
            if count_only == 0:
                m = int(0)
                while m < ntri:  # not range(): a run-time bound costs a step-sign test per iteration
                    for s in range(3):
                        le = tri_local[start + 3 * m + s]
                        # the edge's voxel lies in this block or one of its 7 upper neighbours:
                        # its block from `codes`, as slot() finds it through the block grid
                        lx = li + edge_offset[le, 0]
                        ly = lj + edge_offset[le, 1]
                        lz = z + edge_offset[le, 2]
                        ox = lx >> 3
                        oy = ly >> 3
                        oz = lz >> 3
                        code = codes[ox * 4 + oy * 2 + oz]
                        idx = int(-1)
                        if code >= 0:
                            idx = edge_vert[
                                (code * BV + ((lx - ox * BS) * BS + (ly - oy * BS)) * BS + (lz - oz * BS)) * 3
                                + edge_offset[le, 3]
                            ]
                        faces[3 * (first + total + m) + s] = idx
                    m += 1
            total += ntri
        if count_only != 0:
            counts[tid] = total


def match_tiles_by_voxel(bcoord, bmap, phi, nvox: int) -> None:
    """Voxels next to a tile take the tile's sign (within 1e-3 voxel), a voxel per thread."""
    split(wp, match_tiles, nvox, [bcoord, bmap, phi, 1e-3])


def match_tiles_by_block(bcoord, bmap, phi, nvox: int) -> None:
    """match_tiles_by_voxel, a block per thread."""
    launch_blocks(wp, match_tiles_lines, [bcoord, bmap, phi, 1e-3])


def mesh_by_voxel(bcoord, bmap, values, tiles, vel, w, grid: SparseGrid) -> tuple | None:
    """Marching cubes over active cells: (world, normals, velocities, faces) device arrays of
    exact size, or None for an empty surface (w: the kernel weight sums, which say where the
    velocity field vel holds a velocity). A thread per edge and per cell, counted per edge and cell."""
    nvox = values.shape[0]
    if nvox == 0:
        return None
    vin = fin = [values, *tiles]

    def run(kernel, dim, inputs):
        split(wp, kernel, dim, inputs)

    return _march(bcoord, bmap, values, tiles, vel, w, grid, (mc_vertices, nvox * 3, vin), (mc_faces, nvox, fin), run)


def mesh_by_block(bcoord, bmap, values, tiles, vel, w, grid: SparseGrid) -> tuple | None:
    """mesh_by_voxel, a block per thread, counted per block line along z (its 24 edges and 8
    cells); the corner signs found once per line, 9 bits each (sign_columns)."""
    nvox = values.shape[0]
    if nvox == 0:
        return None
    masks = wp.empty(nvox // BS, dtype=wp.int32)
    launch_blocks(wp, sign_columns, [bcoord, bmap, rows(values), *tiles, masks], light=True)
    vin, fin = [values, *tiles, masks], [masks, *tiles]

    def run(kernel, dim, inputs):
        launch_blocks(wp, kernel, inputs)

    return _march(
        bcoord,
        bmap,
        values,
        tiles,
        vel,
        w,
        grid,
        (mc_vertices_lines, nvox // BS, vin),
        (mc_faces_lines, nvox // BS, fin),
        run,
    )


def _march(bcoord, bmap, values, tiles, vel, w, grid: SparseGrid, vertices: tuple, cells: tuple, run) -> tuple | None:
    """The marching cubes' passes: vertices (kernel, threads, inputs) and cells (the same for
    the faces), each run twice (count, then write) by run(kernel, threads, inputs)."""
    (kv, nv, vin), (kf, nf, fin) = vertices, cells
    nvox = values.shape[0]
    ecount = wp.empty(nv, dtype=wp.int32)
    edge_vert = wp.empty(nvox * 3, dtype=wp.int32)
    run(kv, nv, [bcoord, bmap, *vin, ecount, 1, ecount, edge_vert, None])
    eoff = scan(wp, ecount, inclusive=True)
    tables = list(device_tables(wp, values.device))
    fcount = wp.empty(nf, dtype=wp.int32)
    run(kf, nf, [bcoord, bmap, *fin, edge_vert, *tables, fcount, 1, fcount, None])
    foff = scan(wp, fcount, inclusive=True)
    m, k = (int(a[-1:].numpy()[0]) for a in (eoff, foff))  # the two sizes: one sync each
    if m == 0 or k == 0:
        return None
    verts = wp.empty(m, dtype=wp.vec3)
    run(kv, nv, [bcoord, bmap, *vin, eoff, 0, ecount, edge_vert, verts])
    faces = wp.empty(3 * k, dtype=wp.int32)
    run(kf, nf, [bcoord, bmap, *fin, edge_vert, *tables, foff, 0, fcount, faces])
    world, normals, velocities = (wp.empty(m, dtype=wp.vec3) for _ in range(3))
    vel_arg = vel if vel is not None else wp.zeros(1, dtype=wp.vec3)
    origin = wp.vec3(*grid.origin.astype(np.float32))
    split(
        wp,
        sample_vertices,
        m,
        [bmap, values, *tiles, vel_arg, w, int(vel is not None), verts, origin, grid.voxel, world, normals, velocities],
    )
    return world, normals, velocities, faces
