"""Gather (part of the field pass): the Zhu-Bridson field at the active voxels from the particles of
the gather cells within the kernel's reach (no atomics).

GPU: a voxel per thread (gather_zhu_bridson). CPU: a block per thread (gather_zhu_bridson_blocks),
each candidate particle fetched once per block and added to the block's lines of 8 voxels
along z. The anisotropic gather (:mod:`mpmfx.surface.aniso_kernels`) is the same on both.
"""

from __future__ import annotations

import warp as wp

from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import launch_split_scratch
from mpmfx.surface.lines import fmax, fmin, vec8
from mpmfx.surface.voxels import BS, BV, CS, voxel_of

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


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
def column_slots(
    x: wp.vec3,
    r2: float,
    bi: int,
    bj: int,
    lo: int,
    hi: int,
    cells: wp.array3d(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
):
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
def write_field(
    t: int,
    w: float,
    dw: wp.vec3,
    gw: wp.vec3,
    vw: wp.vec3,
    radius: float,
    with_v: int,
    far_vox: float,
    phi: wp.array(dtype=float),
    w_out: wp.array(dtype=float),
    offset: wp.array(dtype=wp.vec3),
    vel: wp.array(dtype=wp.vec3),
):
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
    gs, vs: positions (grid units) and velocities in the cells' order (binning.sorted_positions),
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
def write_sums_line(
    t: int,
    acc: wp.array2d(dtype=vec8),
    l: int,
    with_v: int,
    w_out: wp.array(dtype=float),
    offset: wp.array(dtype=wp.vec3),
    vel: wp.array(dtype=wp.vec3),
):
    """write_field without phi for the 8 voxels t .. t + 7 of line l's sums (acc[l, 0]: w, 1-3:
    the offset's, 7-9: the velocity's): w, the offset x - xbar = -dw / w and the mean velocity
    vw / w, 0 where w <= 0. The divisions run as vec8 operations, each lane the voxel kernel's
    own division (the same bits), and w <= 0 is a select, not a branch per voxel (these stores
    took 10.7 ms of the torus "fine" gather's 74, one thread)."""
    w8 = acc[l, 0]
    ox = wp.cw_div(-acc[l, 1], w8)
    oy = wp.cw_div(-acc[l, 2], w8)
    oz = wp.cw_div(-acc[l, 3], w8)
    vx = vec8(0.0)
    vy = vec8(0.0)
    vz = vec8(0.0)
    if with_v != 0:
        vx = wp.cw_div(acc[l, 7], w8)
        vy = wp.cw_div(acc[l, 8], w8)
        vz = wp.cw_div(acc[l, 9], w8)
    for z in range(BS):
        pos = w8[z] > 0.0  # w is a sum of non-negative weights, never NaN
        w_out[t + z] = w8[z]
        offset[t + z] = wp.vec3(wp.where(pos, ox[z], 0.0), wp.where(pos, oy[z], 0.0), wp.where(pos, oz[z], 0.0))
        if with_v != 0:
            vel[t + z] = wp.vec3(wp.where(pos, vx[z], 0.0), wp.where(pos, vy[z], 0.0), wp.where(pos, vz[z], 0.0))


@wp.func
def lane_d2min(p: float, c: int):
    """The least (p - float(i))^2 over the lanes i = c .. c + 7 of a block (voxels^2), as the
    lanes compute it: the float difference and square are monotone in i's distance to p, so
    the least is at floor(p) or floor(p) + 1 clamped to the lanes; the clamps run in floats
    (whole numbers, exact) because Warp's integer min / max compiled to branches here."""
    lo = float(c)
    hi = float(c + BS - 1)
    f = wp.floor(p)
    da = p - fmin(fmax(f, lo), hi)
    db = p - fmin(fmax(f + 1.0, lo), hi)
    return fmin(da * da, db * db)


@wp.func
def lane_mask(a: float, sq: vec8, b: float, r2: float):
    """Bit z set where (a + sq[z]) + b < r2: the lanes of a row (or the rows of a block) a
    particle's kernel reaches (gather_zhu_bridson_blocks' test, lane by lane)."""
    m = int(0)
    for z in range(BS):
        m = m | wp.where((a + sq[z]) + b < r2, 1 << z, 0)
    return m


@wp.func
def add_particle(gp: wp.vec3, vp: wp.vec3, c: wp.vec3i, r2: float, with_v: int, grad: int, acc: wp.array2d(dtype=vec8)):
    """Adds the particle at gp (grid coordinates, voxels; velocity vp) to the sums acc of the
    lines of the block at voxel c that its kernel reaches (gather_zhu_bridson_blocks)."""
    dzv = vec8(0.0)
    dyv = vec8(0.0)
    dxv = vec8(0.0)
    for z in range(BS):
        dzv[z] = gp[2] - float(c[2] + z)
        dyv[z] = gp[1] - float(c[1] + z)
        dxv[z] = gp[0] - float(c[0] + z)
    dz2 = wp.cw_mul(dzv, dzv)
    dy2 = wp.cw_mul(dyv, dyv)
    dx2 = wp.cw_mul(dxv, dxv)
    dz2min = lane_d2min(gp[2], c[2])
    # a line (i, j) is reached where (dx^2 + dy^2) + the least dz^2 < r2 (with a smaller sum
    # its voxels' weights would all be masked to 0); the sum is monotone in |dx| and |dy|, so
    # the rows reached (at the nearest j) are one run of bits, and so are a row's lines: no
    # test and mispredicted branch per line in a box around the kernel
    rows = lane_mask(lane_d2min(gp[1], c[1]), dx2, dz2min, r2)
    i = wp.bit_count((rows & (-rows)) - 1)
    i_end = i + wp.bit_count(rows)
    # the lines reached as one 64-bit mask (bit i * 8 + j), visited lowest set bit first: one
    # loop for all of them, where a loop per row would mispredict its exit once a row.
    # While, not range(): Warp's range() with bounds known only at run time steps a (start,
    # end, step) triple and tests the step's sign every iteration
    lines = wp.uint64(0)
    while i < i_end:
        lines = lines | (wp.uint64(lane_mask(dx2[i], dy2, dz2min, r2)) << wp.uint64(i * BS))
        i += 1
    while lines != wp.uint64(0):
        la = wp.bit_count((lines & (~lines + wp.uint64(1))) - wp.uint64(1))  # the lowest set bit's index
        lines = lines & (lines - wp.uint64(1))
        i = la >> 3
        j = la & 7
        dx = dxv[i]
        dy = dyv[j]
        dxy = dx2[i] + dy2[j]
        u = vec8(0.0)
        for z in range(BS):
            d2 = dxy + dz2[z]
            u[z] = wp.where(d2 < r2, 1.0 - d2 / r2, 0.0)
        uu = wp.cw_mul(u, u)
        wk = wp.cw_mul(uu, u)
        acc[la, 0] = acc[la, 0] + wk
        acc[la, 1] = acc[la, 1] + dx * wk
        acc[la, 2] = acc[la, 2] + dy * wk
        acc[la, 3] = acc[la, 3] + wp.cw_mul(wk, dzv)
        if grad != 0:
            acc[la, 4] = acc[la, 4] + dx * uu
            acc[la, 5] = acc[la, 5] + dy * uu
            acc[la, 6] = acc[la, 6] + wp.cw_mul(uu, dzv)
        if with_v != 0:
            acc[la, 7] = acc[la, 7] + vp[0] * wk
            acc[la, 8] = acc[la, 8] + vp[1] * wk
            acc[la, 9] = acc[la, 9] + vp[2] * wk


@cpu_kernel
def gather_zhu_bridson_blocks(
    bcoord: wp.array(dtype=wp.vec3i),
    cells: wp.array3d(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
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
    nacc: int,
    grad: int,
    acc: wp.array2d(dtype=vec8),
    base: int,
):
    """gather_zhu_bridson for the 512 voxels of one block (thread = active
    block): each candidate particle of the cells within reach of the block is fetched once and
    added to the voxels it reaches, a line of 8 voxels along z at a time (add_particle). A
    voxel's contributing particles all lie in the cells within reach of the voxel, which are a
    subset of the block's visited in the same (cell, then slot) order, so each voxel sums the
    same particles in the same order with the same arithmetic as the voxel kernel: the same
    field bit for bit. g and v are in the sorted order (g[q] = the positions' [order[q]],
    binning.sorted_copy): the fetches run through memory in order instead of jumping.

    A candidate goes on only if its kernel reaches a line of the block, tested exactly at the
    nearest line (lane_d2min; the test is monotone in the distance): 42 % of the candidates
    do on a lattice torus at "fine", and the lines they reach come as bits of one mask
    (add_particle). w, the offset and the velocity are bitwise the voxel kernel's.

    acc: scratch, nacc (7, or 10 with velocities) vec8 sums per line of the block (w, the
    offset's x y z, the weight gradient's x y z, the velocity's x y z; acc[line, sum]), turned
    into the field by the block's last step. grad = 0: the weight gradient is not summed and
    phi not written (write_sums_line): where the normal comes from the blurred weights
    (SparseGrid.normal_passes > 0, every shipped setting) project_on_wide_normal_lines
    overwrites every voxel's phi, and only w, the offset and the velocity reach it.
    Two-dimensional so that a line's sums share one index (Warp wraps every negative index:
    acc[la + k] cost a compare and a conditional move per sum). One block's worth, (64, nacc),
    that every thread of the launch reuses: a CPU launch runs its threads one after another
    (this kernel is the CPU path's only), so the 14 KB stay in L1 (one CPU thread's chunks
    share one: launch.launch_split_scratch). A particle adds to all 8 voxels of a line it
    reaches, the weights of voxels beyond the kernel masked to 0: adding +-0 leaves a sum as
    it is, and the mask is the voxel kernel's test d2 < r2, so the sums stay the voxel
    kernel's bit for bit; the masked line is fixed-length and vectorises."""
    b = wp.tid() + base
    c = bcoord[b] * BS
    t0 = b * BV
    r2 = reach * reach
    for q in range(BS * BS):
        for k in range(nacc):
            acc[q, k] = vec8(0.0)
    shape = wp.vec3i(cells.shape[0], cells.shape[1], cells.shape[2])
    lo = wp.vec3i(0)
    hi = wp.vec3i(0)
    for a in range(3):
        lo[a] = wp.max(int(wp.floor((float(c[a]) - reach) / float(CS))), 0)
        hi[a] = wp.min(int(wp.floor((float(c[a] + BS - 1) + reach) / float(CS))), shape[a] - 1)
    for bi in range(lo[0], hi[0] + 1):
        for bj in range(lo[1], hi[1] + 1):
            # the cells lo[2] .. hi[2] of this (bi, bj) hold consecutive slots (particles sorted
            # by cell, starts their exclusive scan): one loop over them in the same order, where
            # a loop per cell mispredicted its exit once a cell (~0.5 M cells at 100k "fine")
            lin = (bi * shape[1] + bj) * shape[2]
            q = starts[lin + lo[2]]
            end = starts[lin + hi[2]] + cells[bi, bj, hi[2]]
            while q < end:
                gp = g[q]
                # the nearest line's (dx^2 + dy^2) + the least dz^2, as add_particle sums it
                near = (lane_d2min(gp[0], c[0]) + lane_d2min(gp[1], c[1])) + lane_d2min(gp[2], c[2])
                if near < r2:
                    vp = wp.vec3(0.0)
                    if with_v != 0:
                        vp = v[q]
                    add_particle(gp, vp, c, r2, with_v, grad, acc)
                q += 1
    if grad == 0:
        for l in range(BS * BS):
            write_sums_line(t0 + l * BS, acc, l, with_v, w_out, offset, vel)
        return
    for q in range(BV):
        la = q // BS
        z = q - la * BS
        vw = wp.vec3(0.0)
        if with_v != 0:
            vw = wp.vec3(acc[la, 7][z], acc[la, 8][z], acc[la, 9][z])
        write_field(
            t0 + q,
            acc[la, 0][z],
            wp.vec3(acc[la, 1][z], acc[la, 2][z], acc[la, 3][z]),
            wp.vec3(acc[la, 4][z], acc[la, 5][z], acc[la, 6][z]),
            vw,
            radius_vox,
            with_v,
            far_vox,
            phi,
            w_out,
            offset,
            vel,
        )


def gather_by_voxel(bcoord, cells, starts, gs, vs, with_v: int, grid, phi, w, offset, vel) -> None:
    """The isotropic field at the active voxels, a voxel per thread: phi, w (kernel weight sums),
    offset and vel (with_v) filled. gs, vs: the particles' grid positions and velocities in the
    gather cells' order."""
    wp.launch(
        gather_zhu_bridson,
        phi.shape[0],
        inputs=[bcoord, cells, starts, gs, vs, with_v, grid.kernel_vox, grid.r_vox, grid.far_vox],
        outputs=[phi, w, offset, vel],
    )


def gather_by_block(bcoord, cells, starts, gs, vs, with_v: int, grid, phi, w, offset, vel) -> None:
    """gather_by_voxel' field, a block per thread: each candidate particle fetched once per block."""
    nacc = 10 if with_v else 7  # vec8 sums per line: w, offset, weight gradient (, velocity)
    launch_split_scratch(
        wp,
        gather_zhu_bridson_blocks,
        bcoord.shape[0],
        [
            bcoord,
            cells,
            starts,
            gs,
            vs,
            int(with_v),
            grid.kernel_vox,
            grid.r_vox,
            grid.far_vox,
            phi,
            w,
            offset,
            vel,
            nacc,
            int(grid.normal_passes == 0),
        ],  # else phi comes from the wide normal
        lambda: wp.empty((BS * BS, nacc), dtype=vec8),
        device=phi.device,
    )
