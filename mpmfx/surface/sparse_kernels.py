"""Warp kernels of the sparse (block) surfacer: binning, field, topology, smoothing (marching
cubes and output compaction live in :mod:`mpmfx.surface.sparse_mesh_kernels`).

Layout: the grid is cut into blocks of 8^3 voxels (an OpenVDB leaf). `bmap[bi, bj, bk]` holds
the index of an active block (>= 0) or a constant tile: OUTSIDE (-1) or INSIDE (-2). Voxel
data of active block b live at `data[b * 512 + (li * 8 + lj) * 8 + lk]`. Voxel (i, j, k) sits at
grid coordinates (i, j, k), i.e. world `origin + (i, j, k) * voxel` as in the dense surfacer.
"""

import warp as wp

BS = wp.constant(8)  # block edge in voxels
CS = wp.constant(4)  # edge of the cells particles are binned in for the field gather, voxels
BV = wp.constant(512)  # voxels per block
COUNT_NUDGE = wp.constant(0.01)  # voxels: float32 rounding of grid coordinates up to ~1e5 voxels (count_blocks)
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
def get(bmap: wp.array3d(dtype=wp.int32), data: wp.array(dtype=float), i: int, j: int, k: int, out_v: float, in_v: float):
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
def step_get(bmap: wp.array3d(dtype=wp.int32), data: wp.array(dtype=float), t: int, c: wp.vec3i, axis: int, sgn: int,
             out_v: float, in_v: float):
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
    if bc[0] < 0 or bc[1] < 0 or bc[2] < 0 or bc[0] >= bmap.shape[0] or bc[1] >= bmap.shape[1] or bc[2] >= bmap.shape[2]:
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
def cell_range(x: wp.vec3, reach: float, shape: wp.vec3i):
    """(lo, hi) gather-cell indices (CS^3 voxels each) within `reach` voxels of x, clipped."""
    lo = wp.vec3i(0)
    hi = wp.vec3i(0)
    for a in range(3):
        lo[a] = wp.max(int(wp.floor((x[a] - reach) / float(CS))), 0)
        hi[a] = wp.min(int(wp.floor((x[a] + reach) / float(CS))), shape[a] - 1)
    return lo, hi


@wp.func
def column_slots(x: wp.vec3, r2: float, bi: int, bj: int, lo: int, hi: int, cells: wp.array3d(dtype=wp.int32),
                 starts: wp.array(dtype=wp.int32)):
    """(first, end) sorted slots of the particles in gather cells (bi, bj, lo..hi) that may lie
    within sqrt(r2) voxels of x: the cells along z that the ball around x reaches in the column,
    which hold consecutive slots (particles sorted by cell, starts their exclusive scan), so
    one loop runs over them in the cells' order. The cube of cells that cell_range spans holds
    a third more cells than the ball reaches; a particle of a skipped cell lies at least that
    cell's box distance from x, more than sqrt(r2) (0.001 voxel^2 of slack for float
    rounding), so a gather sums the same particles in the same order as over the cube."""
    e = wp.vec2(0.0)
    for a in range(2):
        b = wp.where(a == 0, bi, bj)
        e[a] = wp.max(wp.max(float(b * CS) - x[a], x[a] - float(b * CS + CS)), 0.0)
    rest = r2 + 0.001 - wp.dot(e, e)
    if rest <= 0.0:
        return 0, 0
    rz = wp.sqrt(rest)
    k0 = wp.max(int(wp.floor((x[2] - rz) / float(CS))), lo)
    k1 = wp.min(int(wp.floor((x[2] + rz) / float(CS))), hi)
    if k1 < k0:
        return 0, 0
    lin = (bi * cells.shape[1] + bj) * cells.shape[2]
    return starts[lin + k0], starts[lin + k1] + cells[bi, bj, k1]


@wp.func
def write_field(t: int, w: float, dw: wp.vec3, gw: wp.vec3, vw: wp.vec3, radius: float, with_v: int,
                far_vox: float, phi: wp.array(dtype=float), w_out: wp.array(dtype=float),
                offset: wp.array(dtype=wp.vec3), vel: wp.array(dtype=wp.vec3)):
    """Voxel t's Zhu-Bridson phi from its gathered sums (w, dw = sum w (x_p - x), gw the
    weight gradient, vw = sum w v_p): -(x - xbar) . n - radius, n = -gw / |gw|; far_vox
    where no particle reaches. Also w, the offset x - xbar and the mean velocity."""
    w_out[t] = w
    if w <= 0.0:
        phi[t] = far_vox
        offset[t] = wp.vec3(0.0)
        if with_v != 0:
            vel[t] = wp.vec3(0.0)
        return
    d = -dw / w  # x - xbar
    offset[t] = d
    dist = wp.length(d)
    gl = wp.length(gw)
    if gl > 0.0:
        dist = -wp.dot(d, gw) / gl  # gw points inward (towards the particles)
    phi[t] = dist - radius
    if with_v != 0:
        vel[t] = vw / w


@wp.kernel
def bounds(x: wp.array(dtype=wp.vec3), threads: int, out: wp.array(dtype=float)):
    """out[0:3] = min, out[3:6] = max of the finite positions, out[6] += count of non-finite
    ones; each thread reduces x[t], x[t + threads], ... (coalesced), then 7 atomics."""
    t = wp.tid()
    lo = wp.vec3(1.0e30)
    hi = wp.vec3(-1.0e30)
    bad = float(0.0)
    for p in range(t, x.shape[0], threads):
        q = x[p]
        if wp.isfinite(q[0]) and wp.isfinite(q[1]) and wp.isfinite(q[2]):
            lo = wp.min(lo, q)
            hi = wp.max(hi, q)
        else:
            bad += 1.0
    for a in range(3):
        wp.atomic_min(out, a, lo[a])
        wp.atomic_max(out, 3 + a, hi[a])
    if bad > 0.0:
        wp.atomic_add(out, 6, bad)


@wp.kernel
def to_grid(x: wp.array(dtype=wp.vec3), origin: wp.vec3, inv_voxel: float, g: wp.array(dtype=wp.vec3)):
    p = wp.tid()
    g[p] = (x[p] - origin) * inv_voxel


@wp.kernel
def count_blocks(
    g: wp.array(dtype=wp.vec3),
    counts: wp.array3d(dtype=wp.int32),
    cells: wp.array3d(dtype=wp.int32),
    keys: wp.array(dtype=wp.int32),
    order: wp.array(dtype=wp.int32),
):
    """Particles per block and per gather cell (CS^3 voxels); keys[p] = linear cell index of
    particle p, order[p] = p (to sort).

    The block counts judge how full a block is (classify_blocks), so a particle within
    COUNT_NUDGE voxels below a block face counts for the block above: a lattice plane lying on a
    block face (x = k h, as lattices laid from 0 do) would otherwise split between the blocks by
    float rounding, 3 and 5 layers instead of 4 and 4 (measured: +74 % active blocks)."""
    p = wp.tid()
    gp = g[p]
    ci = int(wp.floor(gp[0])) // CS
    cj = int(wp.floor(gp[1])) // CS
    ck = int(wp.floor(gp[2])) // CS
    bi = int(wp.floor(gp[0] + COUNT_NUDGE)) // BS
    bj = int(wp.floor(gp[1] + COUNT_NUDGE)) // BS
    bk = int(wp.floor(gp[2] + COUNT_NUDGE)) // BS
    # the grid's margin blocks hold no particle, so bi .. bk stay inside it
    wp.atomic_add(counts, bi, bj, bk, 1)
    wp.atomic_add(cells, ci, cj, ck, 1)
    keys[p] = (ci * cells.shape[1] + cj) * cells.shape[2] + ck
    order[p] = p


@wp.kernel
def mark_near_blocks(g: wp.array(dtype=wp.vec3), reach: float, near: wp.array3d(dtype=wp.int32), base: int):
    """near = 1 on blocks with a voxel within `reach` voxels of a particle (box distance)."""
    p = wp.tid() + base
    gp = g[p]
    lo = wp.vec3i(0)
    hi = wp.vec3i(0)
    for a in range(3):
        lo[a] = wp.max(int(wp.floor((gp[a] - reach) / 8.0)), 0)
        hi[a] = wp.min(int(wp.floor((gp[a] + reach) / 8.0)), near.shape[a] - 1)
    r2 = reach * reach
    for bi in range(lo[0], hi[0] + 1):
        for bj in range(lo[1], hi[1] + 1):
            for bk in range(lo[2], hi[2] + 1):
                if near[bi, bj, bk] == 0:  # most blocks are marked already by a particle before
                    b = wp.vec3i(bi, bj, bk)
                    d2 = float(0.0)
                    for a in range(3):
                        # distance from the particle to the block's voxel span [8 b, 8 b + 7]
                        e = wp.max(wp.max(float(b[a] * BS) - gp[a], gp[a] - float(b[a] * BS + BS - 1)), 0.0)
                        d2 += e * e
                    if d2 <= r2:
                        near[bi, bj, bk] = 1


@wp.kernel
def classify_blocks(
    counts: wp.array3d(dtype=wp.int32),
    near: wp.array3d(dtype=wp.int32),
    dense_reach: int,
    dense_min: int,
    state: wp.array3d(dtype=wp.int32),
):
    """OUTSIDE: no particle near; INSIDE: every block within `dense_reach` holds >= dense_min
    particles (the kernel support is then full, so the field is deep inside); else ACTIVE."""
    i, j, k = wp.tid()
    n = wp.vec3i(counts.shape[0], counts.shape[1], counts.shape[2])
    dense = int(1)
    for a in range(i - dense_reach, i + dense_reach + 1):
        for b in range(j - dense_reach, j + dense_reach + 1):
            for c in range(k - dense_reach, k + dense_reach + 1):
                cnt = int(0)
                if a >= 0 and b >= 0 and c >= 0 and a < n[0] and b < n[1] and c < n[2]:
                    cnt = counts[a, b, c]
                if cnt < dense_min:
                    dense = 0
    s = TILE_ACTIVE
    if near[i, j, k] == 0:
        s = TILE_OUTSIDE
    elif dense == 1:
        s = TILE_INSIDE
    state[i, j, k] = s


@wp.kernel
def outside_block_labels(state: wp.array3d(dtype=wp.int32), labels: wp.array3d(dtype=wp.int32)):
    """Flood-fill seeds over constant-outside blocks: label 0 on the grid's faces, the block's
    linear index + 1 elsewhere. After the sweeps (sweep_block_labels) the blocks the boundary
    reaches hold 0, and each void (the others) the least seed of its blocks: one label a void."""
    i, j, k = wp.tid()
    if state[i, j, k] == TILE_OUTSIDE:
        if i == 0 or j == 0 or k == 0 or i == state.shape[0] - 1 or j == state.shape[1] - 1 or k == state.shape[2] - 1:
            labels[i, j, k] = 0
        else:
            labels[i, j, k] = (i * state.shape[1] + j) * state.shape[2] + k + 1
    else:
        labels[i, j, k] = LABEL_NONE


@wp.kernel
def sweep_block_labels(labels: wp.array3d(dtype=wp.int32), axis: int, reverse: int, changed: wp.array(dtype=wp.int32)):
    """Carry the minimum label along one line of the block grid through labelled blocks.

    Launched over the two other axes; six sweeps (+-x, +-y, +-z) repeated until nothing
    changes label every 6-connected component with its smallest seed (flood fill).
    """
    a, b = wp.tid()
    n = labels.shape[axis]
    carry = int(LABEL_BIG)
    count = int(0)
    for t in range(n):
        s = t
        if reverse != 0:
            s = n - 1 - t
        c = wp.vec3i(s, a, b)
        if axis == 1:
            c = wp.vec3i(a, s, b)
        elif axis == 2:
            c = wp.vec3i(a, b, s)
        lab = labels[c[0], c[1], c[2]]
        if lab == LABEL_NONE:
            carry = LABEL_BIG
        else:
            if carry < lab:
                labels[c[0], c[1], c[2]] = carry
                count += 1
            else:
                carry = lab
    if count > 0:
        changed[0] = 1  # a flag: every writer stores the same value, no atomic contention


@wp.kernel
def count_voids(labels: wp.array3d(dtype=wp.int32), count: wp.array(dtype=wp.int32)):
    """count[0] += the OUTSIDE blocks the grid boundary does not reach (labels above 0 after the
    block flood fill: voids). Most grids have none: no atomic contends."""
    i, j, k = wp.tid()
    if labels[i, j, k] > 0:
        wp.atomic_add(count, 0, 1)


@wp.kernel
def void_shells(labels: wp.array3d(dtype=wp.int32), state: wp.array3d(dtype=wp.int32)):
    """A void's blocks (labels above 0) next to (26-neighbourhood) a block of no void become
    ACTIVE (its shell); the others INSIDE for now (its core: sparse._open_void_cores)."""
    i, j, k = wp.tid()
    if labels[i, j, k] <= 0:
        return
    shell = int(0)
    for n in range(27):
        a = i + n // 9 - 1
        b = j + (n // 3) % 3 - 1
        c = k + n % 3 - 1
        if labels[a, b, c] <= 0:  # a void never touches the grid's faces: its neighbours are in the grid
            shell = 1
    state[i, j, k] = wp.where(shell != 0, TILE_ACTIVE, TILE_INSIDE)


@wp.kernel
def void_openness(labels: wp.array3d(dtype=wp.int32), bmap: wp.array3d(dtype=wp.int32), phi: wp.array(dtype=float),
                  open_: wp.array(dtype=wp.int32)):
    """open_[a void's label] = 1 where a voxel of its shell is outside after the topology's
    bubble fill: the void joins the outside through gaps in its surface. A sealed void's shell
    is all inside then (filled as a bubble)."""
    i, j, k = wp.tid()
    lab = labels[i, j, k]
    if lab <= 0:
        return
    b = bmap[i, j, k]
    if b < 0:
        return
    for q in range(BV):
        if phi[b * BV + q] > 0.0:
            open_[lab] = 1
            return


@wp.kernel
def open_void_cores(labels: wp.array3d(dtype=wp.int32), open_: wp.array(dtype=wp.int32), bmap: wp.array3d(dtype=wp.int32)):
    """A void's core (INSIDE tiles) becomes OUTSIDE where the void is open (void_openness)."""
    i, j, k = wp.tid()
    lab = labels[i, j, k]
    if lab > 0 and bmap[i, j, k] == TILE_INSIDE and open_[lab] != 0:
        bmap[i, j, k] = TILE_OUTSIDE


@wp.kernel
def compact_blocks(
    state: wp.array3d(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    bmap: wp.array3d(dtype=wp.int32),
    bcoord: wp.array(dtype=wp.vec3i),
):
    """bmap = active index (exclusive scan of ACTIVE flags) or a constant tile."""
    i, j, k = wp.tid()
    s = state[i, j, k]
    if s == TILE_ACTIVE:
        lin = (i * state.shape[1] + j) * state.shape[2] + k
        b = offsets[lin]
        bmap[i, j, k] = b
        bcoord[b] = wp.vec3i(i, j, k)
    else:
        bmap[i, j, k] = s


@wp.kernel
def active_flags(state: wp.array3d(dtype=wp.int32), flags: wp.array(dtype=wp.int32)):
    i, j, k = wp.tid()
    flags[(i * state.shape[1] + j) * state.shape[2] + k] = wp.where(state[i, j, k] == TILE_ACTIVE, 1, 0)


@wp.kernel
def sorted_copy(src: wp.array(dtype=wp.vec3), order: wp.array(dtype=wp.int32), dst: wp.array(dtype=wp.vec3), base: int):
    """dst[q] = src[order[q]]."""
    q = wp.tid() + base
    dst[q] = src[order[q]]


@wp.kernel
def gather_zhu_bridson(
    bcoord: wp.array(dtype=wp.vec3i),
    cells: wp.array3d(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    gs: wp.array(dtype=wp.vec3),
    vs: wp.array(dtype=wp.vec3),
    with_v: int,
    reach: float,
    radius_vox: float,
    far_vox: float,
    phi: wp.array(dtype=float),
    w_out: wp.array(dtype=float),
    offset: wp.array(dtype=wp.vec3),
    vel: wp.array(dtype=wp.vec3),
):
    """Zhu-Bridson phi at one active voxel, gathered from particles of the nearby cells (CS^3
    voxels each: a finer bin than the blocks, so few particles beyond the kernel are visited).
    gs, vs: positions (grid units) and velocities in the cells' order (sparse._sorted_positions),
    so a cell's particles are read from consecutive memory.

    phi = -(x - xbar) . n - r with n = -grad w / |grad w| (analytic kernel gradient). Projecting
    on the normal matters on irregular samples: xbar jitters sideways as much as along the
    normal, and |x - xbar| would turn that sideways jitter into an outward bias.
    """
    t = wp.tid()
    c = voxel_of(t, bcoord)
    x = wp.vec3(float(c[0]), float(c[1]), float(c[2]))
    r2 = reach * reach
    lo, hi = cell_range(x, reach, wp.vec3i(cells.shape[0], cells.shape[1], cells.shape[2]))
    w = float(0.0)
    dw = wp.vec3(0.0)  # sum w * (x_p - x)
    gw = wp.vec3(0.0)  # gradient of w (up to the factor 6 / R^2)
    vw = wp.vec3(0.0)
    for bi in range(lo[0], hi[0] + 1):
        for bj in range(lo[1], hi[1] + 1):
            q, end = column_slots(x, r2, bi, bj, lo[2], hi[2], cells, starts)
            while q < end:
                d = gs[q] - x
                d2 = wp.dot(d, d)
                if d2 < r2:
                    u = 1.0 - d2 / r2
                    wk = u * u * u
                    w += wk
                    dw += wk * d
                    gw += (u * u) * d
                    if with_v != 0:
                        vw += wk * vs[q]
                q += 1
    write_field(t, w, dw, gw, vw, radius_vox, with_v, far_vox, phi, w_out, offset, vel)


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


@wp.kernel
def blur_weight_axis(
    bcoord: wp.array(dtype=wp.vec3i), bmap: wp.array3d(dtype=wp.int32), src: wp.array(dtype=float), axis: int,
    step: int, dst: wp.array(dtype=float), base: int,
):
    """dst = [1 2 1]/4 blur of the kernel weight sum along `axis` with taps `step` (< BS) voxels
    apart (variance 0.5 step^2 voxel^2; tiles as in weight_at), on the 8 voxels of one line
    along `axis` (thread = line, 64 a block): the blocks before and after the line are looked
    up once, not by every voxel within `step` of the block's faces (10M random torus "fine", one
    H200: 21 passes 12.6 ms with a voxel per thread)."""
    q = wp.tid() + base
    b = q // 64
    first, st = line_start(axis, q - b * 64)
    t0 = b * BV + first
    below = wp.vec3i(bcoord[b][0], bcoord[b][1], bcoord[b][2])
    above = wp.vec3i(below[0], below[1], below[2])
    below[axis] = below[axis] - 1
    above[axis] = above[axis] + 1
    lo = block_tile(bmap, below)
    hi = block_tile(bmap, above)
    for i in range(BS):
        t = t0 + i * st
        v = src[t]
        a = float(0.0)
        if i >= step:  # the tap lies in the same block
            a = src[t - step * st]
        elif lo >= 0:  # the same line of the block before, BS - step voxels on
            a = src[lo * BV + t - b * BV + (BS - step) * st]
        elif lo == TILE_INSIDE:
            a = v
        c = float(0.0)
        if i + step < BS:
            c = src[t + step * st]
        elif hi >= 0:
            c = src[hi * BV + t - b * BV - (BS - step) * st]
        elif hi == TILE_INSIDE:
            c = v
        dst[t] = 0.25 * a + 0.5 * v + 0.25 * c


@wp.kernel
def project_on_wide_normal(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    wide: wp.array(dtype=float),
    w: wp.array(dtype=float),
    offset: wp.array(dtype=wp.vec3),
    radius_vox: float,
    far_vox: float,
    aniso: int,
    cov: wp.array(dtype=wp.mat33),
    cov_iters: int,
    cov_eps: float,
    radius: wp.array(dtype=float),
    phi: wp.array(dtype=float),
    base: int,
):
    """phi = -(x - xbar) . n - r with n = -grad(wide) / |grad(wide)|, `wide` the kernel weight sum
    blurred to a wider kernel. The normal of the kernel itself is estimated from the same
    particles with nearly the same weights as xbar, so on irregular samples their sideways
    errors correlate and the projected distance reads long (the surface sits ~0.1 h inside);
    a wider kernel's normal decorrelates them and leaves lattices as they were.

    aniso != 0 (anisotropic kernels): n is turned towards the thinnest axis of the neighbours'
    covariance `cov` by `cov_iters` inverse-power iterations (cov + cov_eps I, voxels^2), and r
    is the voxel's own `radius`. Inside a one-particle-thick sheet the blurred weights have no
    gradient across the sheet, so the wide normal lies in the sheet, and projecting xbar's
    sideways offset on it opened holes (88 in the bench's random sheet); the thinnest axis is
    the sheet's normal there, and the surface's normal on bodies. (The iterations start from
    the wide normal; inside a sheet its only component across the sheet comes from the 2-voxel
    ripple the weight blur's 2-voxel taps keep: a blur without it left n in the sheet's plane,
    docs/surfacing-log.md, sixteenth step.)"""
    t = wp.tid() + base
    if w[t] <= 0.0:
        phi[t] = far_vox
        return
    c = voxel_of(t, bcoord)
    g = wp.vec3(0.0)
    for a in range(3):
        o = wp.vec3i(0)
        o[a] = 1
        g[a] = weight_at(bmap, wide, t, c[0] + o[0], c[1] + o[1], c[2] + o[2]) - weight_at(
            bmap, wide, t, c[0] - o[0], c[1] - o[1], c[2] - o[2])
    if aniso != 0:
        ci = wp.inverse(cov[t] + cov_eps * wp.identity(n=3, dtype=float))
        for it in range(cov_iters):
            g = ci * g
            g = g / wp.max(wp.length(g), 1.0e-20)
    d = offset[t]
    dist = wp.length(d)
    gl = wp.length(g)
    if gl > 0.0:
        dist = -wp.dot(d, g) / gl  # g points inward (towards the particles)
    r = radius_vox
    if aniso != 0:
        r = radius[t]
    phi[t] = dist - r


@wp.func
def edge_limit(full: float, gate: float, noise: float):
    """How far (voxels) the smoothing may move a voxel's surface inward: `full` on faces and
    curves; at an edge (gate 1, mpmfx.surface.edge_kernels) no further than the noise of its
    block's samples, or `full` where the block saw none (noise < 0)."""
    lim = full
    if noise >= 0.0:
        lim = wp.min(full, noise)
    return full + (lim - full) * gate


@wp.func
def gate_cell(b: int, i: int, j: int, k: int):
    """Index of the 2^3-voxel cell (edge_kernels.edge_gate) of voxel (i, j, k) of active block b."""
    return b * 64 + (i // 2) * 16 + (j // 2) * 4 + k // 2


@wp.kernel
def limit_inward(a: wp.array(dtype=float), ref: wp.array(dtype=float), full: float, gate: wp.array(dtype=float),
                 noise: wp.array(dtype=float), base: int):
    """a = min(a, ref + edge_limit): the level set a (signed distance, negative inside) lies at
    most that far inside ref's; gate is per 2^3-voxel cell, noise per active block."""
    t = wp.tid() + base
    b = t // BV
    l = t - b * BV
    g = gate[gate_cell(b, l // 64, (l // 8) % 8, l % 8)]
    a[t] = wp.min(a[t], ref[t] + edge_limit(full, g, noise[b]))


@wp.func
def flow_step(p0: float, xm: float, xp: float, ym: float, yp: float, zm: float, zp: float, fxy: float, fxz: float,
              fyz: float, dt: float, taper: float):
    """p0 after one step of curvature_flow, from its six axis neighbours and the mixed second
    differences (voxels)."""
    gx = 0.5 * (xp - xm)
    gy = 0.5 * (yp - ym)
    gz = 0.5 * (zp - zm)
    fxx = xp - 2.0 * p0 + xm
    fyy = yp - 2.0 * p0 + ym
    fzz = zp - 2.0 * p0 + zm
    g2 = gx * gx + gy * gy + gz * gz
    nhn = float(0.0)
    if g2 > 1.0e-8:
        nhn = (gx * gx * fxx + gy * gy * fyy + gz * gz * fzz + 2.0 * (gx * gy * fxy + gx * gz * fxz + gy * gz * fyz)) / g2
    return p0 + taper * dt * (fxx + fyy + fzz - nhn)


@wp.func
def edge_flow_step(p0: float, xm: float, xp: float, ym: float, yp: float, zm: float, zp: float, fxy: float,
                   fxz: float, fyz: float, dt: float, taper: float, gate: float, pit: float):
    """flow_step where the edge gate is open (gate > 0, edge_kernels.edge_gate): the speed from the
    level set's two principal curvatures, lo (the smaller: along an edge) and hi (across it),
    |grad| (lo + hi) being flow_step's Laplacian less its part along the normal. Where the edge
    is pitted along its length (lo < 0: a sample void in the edge), the across-edge part is
    suppressed by gate x clamp(-lo / pit, 0, 1) (pit: 1/voxel), so the flow fills the pit along
    the edge instead of rounding the whole edge into it: the random box's worst vertices sat in
    such pits (10M "fine" 1.037 -> 0.928 h; docs/surfacing-log.md, nineteenth step)."""
    gx = 0.5 * (xp - xm)
    gy = 0.5 * (yp - ym)
    gz = 0.5 * (zp - zm)
    g2 = gx * gx + gy * gy + gz * gz
    if g2 <= 1.0e-8:
        return flow_step(p0, xm, xp, ym, yp, zm, zp, fxy, fxz, fyz, dt, taper)
    fxx = xp - 2.0 * p0 + xm
    fyy = yp - 2.0 * p0 + ym
    fzz = zp - 2.0 * p0 + zm
    gl = wp.sqrt(g2)
    n = wp.vec3(gx, gy, gz) / gl
    # the curvature matrix P H P / |grad| (P = I - n n^T) through its trace and that of its
    # square, tr(P H P P H P) = tr(H^2) - 2 |H n|^2 + (n^T H n)^2, without forming it
    hn = wp.vec3(fxx * n[0] + fxy * n[1] + fxz * n[2], fxy * n[0] + fyy * n[1] + fyz * n[2], fxz * n[0] + fyz * n[1] + fzz * n[2])
    a = wp.dot(n, hn)
    h2 = fxx * fxx + fyy * fyy + fzz * fzz + 2.0 * (fxy * fxy + fxz * fxz + fyz * fyz)
    tr = (fxx + fyy + fzz - a) / gl
    tr2 = (h2 - 2.0 * wp.dot(hn, hn) + a * a) / g2
    disc = wp.sqrt(wp.max(2.0 * tr2 - tr * tr, 0.0))  # the two eigenvalues' difference
    lo = 0.5 * (tr - disc)
    hi = 0.5 * (tr + disc)
    keep = 1.0 - gate * wp.clamp(-lo / pit, 0.0, 1.0)
    return p0 + taper * dt * gl * (lo + hi * keep)


@wp.func
def flow_taper(p0: float, band: float):
    """The share of a full flow step a value p0 (voxels from the zero level) takes: full steps
    within band - 1 voxel of the zero level, none beyond band, linear between (a hard edge
    made voxels start and stop moving as the surface drifted between frames: p99 normal turn
    7.2 degrees at a 1.5-voxel band)."""
    return wp.clamp(band - wp.abs(p0), 0.0, 1.0)


@wp.kernel
def curvature_flow(bcoord: wp.array(dtype=wp.vec3i), bmap: wp.array3d(dtype=wp.int32), src: wp.array(dtype=float),
                   out_v: float, in_v: float, dt: float, band: float, dst: wp.array(dtype=float), base: int):
    """One explicit step of the level set's mean-curvature flow, phi += dt (Laplacian phi -
    n^T H n) (voxels; n = grad phi / |grad phi|, H the Hessian): the blur's Laplacian without
    its part along the normal, so a flat sheet stays where it is (at a thin part's midplane,
    where the normal flips, n^T H n takes the kink). Only voxels within `band` of the zero level
    move (flow_taper: the surface is what the flow is about; a 2-voxel band instead of 3 made
    the moving box's p99 normal turn between frames 6.8 degrees instead of 5.4). Where the
    edge gate is open, edge_flow then steps the voxels again.

    A thread takes the 8 voxels of one line along z (64 a block): its neighbour lines, and the
    lines above and below it across the block's faces, are found once for the line (a voxel
    per thread with a block-map lookup at every neighbour off its block: 8.7 ms for 8 steps at
    10M "fine" on an H200). The same values in the same operations as `get` per neighbour."""
    q = wp.tid() + base
    b = q // 64
    l = q - b * 64
    t0 = b * BV + l * BS
    moves = bool(False)  # a line with no value within `band` of the zero level stays as it is
    for k in range(BS):
        if flow_taper(src[t0 + k], band) > 0.0:
            moves = True
    if not moves:
        for k in range(BS):
            dst[t0 + k] = src[t0 + k]
        return
    x = l // BS
    y = l - x * BS
    bc = bcoord[b]
    mm = side_line(bmap, bc, b, x - 1, y - 1, 0)
    mp = side_line(bmap, bc, b, x - 1, y + 1, 0)
    pm = side_line(bmap, bc, b, x + 1, y - 1, 0)
    pp = side_line(bmap, bc, b, x + 1, y + 1, 0)
    xm = side_line(bmap, bc, b, x - 1, y, 0)
    xp = side_line(bmap, bc, b, x + 1, y, 0)
    ym = side_line(bmap, bc, b, x, y - 1, 0)
    yp = side_line(bmap, bc, b, x, y + 1, 0)
    own_lo = side_line(bmap, bc, b, x, y, -1)
    own_hi = side_line(bmap, bc, b, x, y, 1)
    xm_lo = side_line(bmap, bc, b, x - 1, y, -1)
    xm_hi = side_line(bmap, bc, b, x - 1, y, 1)
    xp_lo = side_line(bmap, bc, b, x + 1, y, -1)
    xp_hi = side_line(bmap, bc, b, x + 1, y, 1)
    ym_lo = side_line(bmap, bc, b, x, y - 1, -1)
    ym_hi = side_line(bmap, bc, b, x, y - 1, 1)
    yp_lo = side_line(bmap, bc, b, x, y + 1, -1)
    yp_hi = side_line(bmap, bc, b, x, y + 1, 1)
    for k in range(BS):
        t = t0 + k
        p0 = src[t]
        taper = flow_taper(p0, band)
        if taper == 0.0:
            dst[t] = p0
            continue
        fxy = 0.25 * (line_value(src, pp, k, out_v, in_v) - line_value(src, pm, k, out_v, in_v)
                      - line_value(src, mp, k, out_v, in_v) + line_value(src, mm, k, out_v, in_v))
        fxz = 0.25 * (line_z(src, xp, xp_lo, xp_hi, k + 1, out_v, in_v) - line_z(src, xp, xp_lo, xp_hi, k - 1, out_v, in_v)
                      - line_z(src, xm, xm_lo, xm_hi, k + 1, out_v, in_v) + line_z(src, xm, xm_lo, xm_hi, k - 1, out_v, in_v))
        fyz = 0.25 * (line_z(src, yp, yp_lo, yp_hi, k + 1, out_v, in_v) - line_z(src, yp, yp_lo, yp_hi, k - 1, out_v, in_v)
                      - line_z(src, ym, ym_lo, ym_hi, k + 1, out_v, in_v) + line_z(src, ym, ym_lo, ym_hi, k - 1, out_v, in_v))
        vxm = line_value(src, xm, k, out_v, in_v)
        vxp = line_value(src, xp, k, out_v, in_v)
        vym = line_value(src, ym, k, out_v, in_v)
        vyp = line_value(src, yp, k, out_v, in_v)
        vzm = line_z(src, t0, own_lo, own_hi, k - 1, out_v, in_v)
        vzp = line_z(src, t0, own_lo, own_hi, k + 1, out_v, in_v)
        dst[t] = flow_step(p0, vxm, vxp, vym, vyp, vzm, vzp, fxy, fxz, fyz, dt, taper)


@wp.func
def near(bmap: wp.array3d(dtype=wp.int32), data: wp.array(dtype=float), t: int, c: wp.vec3i, dx: int, dy: int, dz: int,
         out_v: float, in_v: float):
    """`get` of voxel c + (dx, dy, dz) (each -1..1), c being active voxel t: read directly when it
    lies in c's block."""
    if in_block(c, wp.vec3i(dx, dy, dz)):
        return data[t + (dx * BS + dy) * BS + dz]
    return get(bmap, data, c[0] + dx, c[1] + dy, c[2] + dz, out_v, in_v)


@wp.kernel
def edge_flow(bcoord: wp.array(dtype=wp.vec3i), bmap: wp.array3d(dtype=wp.int32), src: wp.array(dtype=float),
              out_v: float, in_v: float, dt: float, band: float, gate: wp.array(dtype=float), pit: float,
              dst: wp.array(dtype=float), base: int):
    """After curvature_flow (thread = 2^3-voxel cell, edge_kernels.edge_gate's): the 8 voxels of a
    cell whose edge gate is open take edge_flow_step instead, from the same neighbour values
    (`get`; the CPU: line_kernels.edge_flow_lines).
    Its own launch: inside curvature_flow the edge step's code cost every voxel registers (10M
    "fine" random torus, which has no open gate, on an H200: 8 steps 4.3 -> 6.5 ms; on the CPU
    twice the time)."""
    cell = wp.tid() + base
    g8 = gate[cell]
    if g8 <= 0.0:
        return
    b = cell // 64
    u = cell - b * 64
    q = int(0)
    while q < 8:  # not unrolled (a range() of constant length is): one copy of the edge step
        t = b * BV + ((2 * (u // 16) + q // 4) * BS + 2 * ((u // 4) % 4) + (q // 2) % 2) * BS + 2 * (u % 4) + q % 2
        p0 = src[t]
        taper = flow_taper(p0, band)
        if taper > 0.0:
            c = voxel_of(t, bcoord)
            fxy = 0.25 * (near(bmap, src, t, c, 1, 1, 0, out_v, in_v) - near(bmap, src, t, c, 1, -1, 0, out_v, in_v)
                          - near(bmap, src, t, c, -1, 1, 0, out_v, in_v) + near(bmap, src, t, c, -1, -1, 0, out_v, in_v))
            fxz = 0.25 * (near(bmap, src, t, c, 1, 0, 1, out_v, in_v) - near(bmap, src, t, c, 1, 0, -1, out_v, in_v)
                          - near(bmap, src, t, c, -1, 0, 1, out_v, in_v) + near(bmap, src, t, c, -1, 0, -1, out_v, in_v))
            fyz = 0.25 * (near(bmap, src, t, c, 0, 1, 1, out_v, in_v) - near(bmap, src, t, c, 0, 1, -1, out_v, in_v)
                          - near(bmap, src, t, c, 0, -1, 1, out_v, in_v) + near(bmap, src, t, c, 0, -1, -1, out_v, in_v))
            dst[t] = edge_flow_step(p0, near(bmap, src, t, c, -1, 0, 0, out_v, in_v), near(bmap, src, t, c, 1, 0, 0, out_v, in_v),
                                    near(bmap, src, t, c, 0, -1, 0, out_v, in_v), near(bmap, src, t, c, 0, 1, 0, out_v, in_v),
                                    near(bmap, src, t, c, 0, 0, -1, out_v, in_v), near(bmap, src, t, c, 0, 0, 1, out_v, in_v),
                                    fxy, fxz, fyz, dt, taper, g8, pit)
        q += 1


@wp.kernel
def average_into(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    """a = (a + b) / 2."""
    t = wp.tid()
    a[t] = 0.5 * (a[t] + b[t])


@wp.kernel
def add_scalar(a: wp.array(dtype=float), value: float):
    t = wp.tid()
    a[t] = a[t] + value


@wp.kernel
def add_clamp(a: wp.array(dtype=float), value: float, clip: float):
    """a = clamp(a + value, -clip, clip)."""
    t = wp.tid()
    a[t] = wp.clamp(a[t] + value, -clip, clip)


@wp.kernel
def gate_closing(closed: wp.array(dtype=float), dist: wp.array(dtype=float), lo: float, hi: float):
    """Keep the closing's fill dist - closed only where it is deeper than lo voxels (a lattice
    face's uniform shift, an edge it eroded numerically: dist kept), in full from hi voxels
    (the voids it fills), in part in between (no jump as a fill grows past lo between frames).
    sparse._close_voids."""
    t = wp.tid()
    fill = dist[t] - closed[t]
    w = wp.clamp((fill - lo) / wp.max(hi - lo, 1e-6), 0.0, 1.0)
    closed[t] = dist[t] - w * fill


@wp.kernel
def renormalise(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    scale: float,
    clip: float,
    far: float,
    out: wp.array(dtype=float),
    base: int,
):
    """out = clip(phi / |grad phi| * scale, +-clip): a signed distance near the zero level;
    +-clip where |phi| >= far (phi is a distance there already, but may step to a constant).

    The raw field keeps its sign (so its zero level) but its slope is not 1 (Zhu-Bridson is
    ~0.7 at the surface and 0 deep inside); dividing by the central-difference gradient
    restores distances in the band, clipping handles the flat interior."""
    t = wp.tid() + base
    c = voxel_of(t, bcoord)
    gx = step_get(bmap, phi, t, c, 0, 1, out_v, in_v) - step_get(bmap, phi, t, c, 0, -1, out_v, in_v)
    gy = step_get(bmap, phi, t, c, 1, 1, out_v, in_v) - step_get(bmap, phi, t, c, 1, -1, out_v, in_v)
    gz = step_get(bmap, phi, t, c, 2, 1, out_v, in_v) - step_get(bmap, phi, t, c, 2, -1, out_v, in_v)
    grad = 0.5 * wp.length(wp.vec3(gx, gy, gz))
    v = phi[t]
    out[t] = wp.where(wp.abs(v) >= far, wp.where(v > 0.0, clip, -clip), wp.clamp(v / wp.max(grad, 0.05) * scale, -clip, clip))


@wp.kernel
def match_tiles(bcoord: wp.array(dtype=wp.vec3i), bmap: wp.array3d(dtype=wp.int32), phi: wp.array(dtype=float), eps: float,
                base: int):
    """Give voxels next to a constant tile that tile's sign, so no zero crossing touches a tile
    (marching cubes runs only on cells whose lower corner is active).

    The 26 neighbours of a voxel on its block's boundary fall in at most 7 other blocks, each
    looked up once, in lexicographic order of the block offset: visiting the neighbours one by
    one in (x, y, z) order meets the same blocks in that order, and a block met again changes
    nothing more (10M random torus "fine", one H200: 4.8 ms with a lookup per neighbour)."""
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
