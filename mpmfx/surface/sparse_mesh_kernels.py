"""Warp kernels of the sparse surfacer's output: marching cubes over active blocks, vertex
attributes, and compaction of the blocks to OpenVDB-style leaves / dense arrays.

A second module (the first holds binning, field, topology and smoothing) so each stays small;
it shares the block layout and accessors of :mod:`mpmfx.surface.sparse_kernels`.
"""

import warp as wp

from mpmfx.surface.sparse_kernels import BS, BV, TILE_INSIDE, get, slot, step_get, voxel_of


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


@wp.kernel
def densify(
    bcoord: wp.array(dtype=wp.vec3i),
    data: wp.array(dtype=float),
    lo: wp.vec3i,
    dense: wp.array3d(dtype=float),
):
    """Copy active voxels into a dense array whose [0, 0, 0] is voxel `lo` (pre-filled with tiles)."""
    t = wp.tid()
    c = voxel_of(t, bcoord) - lo
    dense[c[0], c[1], c[2]] = data[t]


@wp.kernel
def densify_vec(bcoord: wp.array(dtype=wp.vec3i), data: wp.array(dtype=wp.vec3), lo: wp.vec3i, dense: wp.array3d(dtype=wp.vec3)):
    t = wp.tid()
    c = voxel_of(t, bcoord) - lo
    dense[c[0], c[1], c[2]] = data[t]


@wp.kernel
def fill_tiles(bmap: wp.array3d(dtype=wp.int32), blo: wp.vec3i, out_v: float, in_v: float, dense: wp.array3d(dtype=float)):
    """Constant-tile value of every voxel of the dense array (active voxels are overwritten)."""
    i, j, k = wp.tid()
    s = bmap[blo[0] + i // BS, blo[1] + j // BS, blo[2] + k // BS]
    dense[i, j, k] = wp.where(s == TILE_INSIDE, in_v, out_v)


@wp.kernel
def classify_output_blocks(values: wp.array(dtype=float), background: float, kind: wp.array(dtype=wp.int32)):
    """kind = 0: every voxel +background (drop), 1: every voxel -background (an inside tile), 2: keep."""
    b = wp.tid()
    n_out = int(0)
    n_in = int(0)
    for q in range(BV):
        v = values[b * BV + q]
        if v >= background:
            n_out += 1
        elif v <= -background:
            n_in += 1
    k = int(2)
    if n_out == BV:
        k = 0
    elif n_in == BV:
        k = 1
    kind[b] = k


@wp.kernel
def gather_blocks(
    keep: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    values: wp.array(dtype=float),
    out: wp.array(dtype=float),
):
    """Copy the voxels of kept blocks (keep[b] == 1) to their compacted slots."""
    t = wp.tid()
    b = t // BV
    if keep[b] != 0:
        out[offsets[b] * BV + t - b * BV] = values[t]


@wp.kernel
def gather_blocks_vec(
    keep: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    values: wp.array(dtype=wp.vec3),
    out: wp.array(dtype=wp.vec3),
):
    t = wp.tid()
    b = t // BV
    if keep[b] != 0:
        out[offsets[b] * BV + t - b * BV] = values[t]


@wp.kernel
def count_negative(a: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32)):
    """count[0] += the entries of a below 0 (count zeroed by the caller)."""
    t = wp.tid()
    if a[t] < 0:
        wp.atomic_add(count, 0, 1)


@wp.kernel
def inside_tiles(bmap: wp.array3d(dtype=wp.int32), flags: wp.array(dtype=wp.int32)):
    """flags = 1 on INSIDE tiles of the block grid, flattened in C order (as numpy's argwhere)."""
    i, j, k = wp.tid()
    flags[(i * bmap.shape[1] + j) * bmap.shape[2] + k] = wp.where(bmap[i, j, k] == TILE_INSIDE, 1, 0)


@wp.kernel
def compact_inside_tiles(bmap: wp.array3d(dtype=wp.int32), flags: wp.array(dtype=wp.int32),
                         offsets: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.vec3i)):
    """out[offsets[b]] = the block coordinates of INSIDE tile b (exclusive scan of flags)."""
    i, j, k = wp.tid()
    b = (i * bmap.shape[1] + j) * bmap.shape[2] + k
    if flags[b] != 0:
        out[offsets[b]] = wp.vec3i(i, j, k)


@wp.kernel
def scan_totals(flags: wp.array(dtype=wp.int32), offsets: wp.array(dtype=wp.int32), slot: int, out: wp.array(dtype=wp.int32)):
    """out[slot] = the sum of flags, from its exclusive scan (one thread)."""
    n = flags.shape[0]
    out[slot] = offsets[n - 1] + flags[n - 1]


@wp.kernel
def kind_equals(kind: wp.array(dtype=wp.int32), value: int, out: wp.array(dtype=wp.int32)):
    b = wp.tid()
    out[b] = wp.where(kind[b] == value, 1, 0)


@wp.kernel
def scale_clamp01(a: wp.array(dtype=float), scale: float):
    """a = clamp(a * scale, 0, 1): a kernel weight sum over its bulk value -> fog density."""
    t = wp.tid()
    a[t] = wp.clamp(a[t] * scale, 0.0, 1.0)
