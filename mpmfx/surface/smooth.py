"""Smoothing pass: the level set's mean-curvature flow over the distance, with the edges'
inward limit (:mod:`mpmfx.surface.edges`). GPU: a voxel or a line per thread; CPU: a block per
thread in rows of 8, the neighbour rows read once."""

from __future__ import annotations

import warp as wp

from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import launch_blocks, split
from mpmfx.surface.lines import block_codes27, ext_row, rows, vec8, vec27i, z_pair
from mpmfx.surface.voxels import BS, BV, gate_cell, get, in_block, line_value, line_z, side_line, voxel_of

FLOW_DT = 0.25  # voxel^2, one smoothing step (curvature_flow): a [1 2 1]/4 pass's spread along the surface
FLOW_BAND = 3.0  # voxels: the smoothing moves the values this close to the zero level (fully within FLOW_BAND - 1)
EDGE_PIT = 0.25  # 1/voxel: a pit along an edge this sharply curved (or more) stops the flow rounding the edge there (edge_flow_step)

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


@wp.func
def edge_limit(full: float, gate: float, noise: float):
    """How far (voxels) the smoothing may move a voxel's surface inward: `full` on faces and
    curves; at an edge (gate 1, mpmfx.surface.edges) no further than the noise of its
    block's samples, or `full` where the block saw none (noise < 0)."""
    lim = full
    if noise >= 0.0:
        lim = wp.min(full, noise)
    return full + (lim - full) * gate


@wp.kernel
def limit_inward(
    a: wp.array(dtype=float),
    ref: wp.array(dtype=float),
    full: float,
    gate: wp.array(dtype=float),
    noise: wp.array(dtype=float),
    base: int,
):
    """a = min(a, ref + edge_limit): the level set a (signed distance, negative inside) lies at
    most that far inside ref's; gate is per 2^3-voxel cell, noise per active block."""
    t = wp.tid() + base
    b = t // BV
    l = t - b * BV
    g = gate[gate_cell(b, l // 64, (l // 8) % 8, l % 8)]
    a[t] = wp.min(a[t], ref[t] + edge_limit(full, g, noise[b]))


@wp.func
def flow_step(
    p0: float,
    xm: float,
    xp: float,
    ym: float,
    yp: float,
    zm: float,
    zp: float,
    fxy: float,
    fxz: float,
    fyz: float,
    dt: float,
    taper: float,
):
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
        nhn = (
            gx * gx * fxx + gy * gy * fyy + gz * gz * fzz + 2.0 * (gx * gy * fxy + gx * gz * fxz + gy * gz * fyz)
        ) / g2
    return p0 + taper * dt * (fxx + fyy + fzz - nhn)


@wp.func
def edge_flow_step(
    p0: float,
    xm: float,
    xp: float,
    ym: float,
    yp: float,
    zm: float,
    zp: float,
    fxy: float,
    fxz: float,
    fyz: float,
    dt: float,
    taper: float,
    gate: float,
    pit: float,
):
    """flow_step where the edge gate is open (gate > 0, edges.edge_gate): the speed from the
    level set's two principal curvatures, lo (the smaller: along an edge) and hi (across it),
    |grad| (lo + hi) being flow_step's Laplacian less its part along the normal. Where the edge
    is pitted along its length (lo < 0: a sample void in the edge), the across-edge part is
    suppressed by gate x clamp(-lo / pit, 0, 1) (pit: 1/voxel), so the flow fills the pit along
    the edge instead of rounding the whole edge into it: the random box's worst vertices sat in
    such pits."""
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
    hn = wp.vec3(
        fxx * n[0] + fxy * n[1] + fxz * n[2], fxy * n[0] + fyy * n[1] + fyz * n[2], fxz * n[0] + fyz * n[1] + fzz * n[2]
    )
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
def curvature_flow(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    dt: float,
    band: float,
    dst: wp.array(dtype=float),
    base: int,
):
    """One explicit step of the level set's mean-curvature flow, phi += dt (Laplacian phi -
    n^T H n) (voxels; n = grad phi / |grad phi|, H the Hessian): the blur's Laplacian without
    its part along the normal, so a flat sheet stays where it is (at a thin part's midplane,
    where the normal flips, n^T H n takes the kink). Only voxels within `band` of the zero level
    move (flow_taper: the surface is what the flow is about; a 2-voxel band instead of 3 made
    the moving box's p99 normal turn between frames 6.8 degrees instead of 5.4). Where the
    edge gate is open, edge_flow then steps the voxels again.

    A thread takes the 8 voxels of one line along z (64 a block): its neighbour lines, and the
    lines above and below it across the block's faces, are found once for the line (a voxel
    per thread would look the block map up at every neighbour off its block). The same values in the same operations as `get` per neighbour."""
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
        fxy = 0.25 * (
            line_value(src, pp, k, out_v, in_v)
            - line_value(src, pm, k, out_v, in_v)
            - line_value(src, mp, k, out_v, in_v)
            + line_value(src, mm, k, out_v, in_v)
        )
        fxz = 0.25 * (
            line_z(src, xp, xp_lo, xp_hi, k + 1, out_v, in_v)
            - line_z(src, xp, xp_lo, xp_hi, k - 1, out_v, in_v)
            - line_z(src, xm, xm_lo, xm_hi, k + 1, out_v, in_v)
            + line_z(src, xm, xm_lo, xm_hi, k - 1, out_v, in_v)
        )
        fyz = 0.25 * (
            line_z(src, yp, yp_lo, yp_hi, k + 1, out_v, in_v)
            - line_z(src, yp, yp_lo, yp_hi, k - 1, out_v, in_v)
            - line_z(src, ym, ym_lo, ym_hi, k + 1, out_v, in_v)
            + line_z(src, ym, ym_lo, ym_hi, k - 1, out_v, in_v)
        )
        vxm = line_value(src, xm, k, out_v, in_v)
        vxp = line_value(src, xp, k, out_v, in_v)
        vym = line_value(src, ym, k, out_v, in_v)
        vyp = line_value(src, yp, k, out_v, in_v)
        vzm = line_z(src, t0, own_lo, own_hi, k - 1, out_v, in_v)
        vzp = line_z(src, t0, own_lo, own_hi, k + 1, out_v, in_v)
        dst[t] = flow_step(p0, vxm, vxp, vym, vyp, vzm, vzp, fxy, fxz, fyz, dt, taper)


@wp.func
def near(
    bmap: wp.array3d(dtype=wp.int32),
    data: wp.array(dtype=float),
    t: int,
    c: wp.vec3i,
    dx: int,
    dy: int,
    dz: int,
    out_v: float,
    in_v: float,
):
    """`get` of voxel c + (dx, dy, dz) (each -1..1), c being active voxel t: read directly when it
    lies in c's block."""
    if in_block(c, wp.vec3i(dx, dy, dz)):
        return data[t + (dx * BS + dy) * BS + dz]
    return get(bmap, data, c[0] + dx, c[1] + dy, c[2] + dz, out_v, in_v)


@wp.kernel
def edge_flow(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    dt: float,
    band: float,
    gate: wp.array(dtype=float),
    pit: float,
    dst: wp.array(dtype=float),
    base: int,
):
    """After curvature_flow (thread = 2^3-voxel cell, edges.edge_gate's): the 8 voxels of a
    cell whose edge gate is open take edge_flow_step instead, from the same neighbour values
    (`get`; the CPU: edge_flow_lines).
    Its own launch: inside curvature_flow the edge step's code would cost every voxel registers."""
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
            fxy = 0.25 * (
                near(bmap, src, t, c, 1, 1, 0, out_v, in_v)
                - near(bmap, src, t, c, 1, -1, 0, out_v, in_v)
                - near(bmap, src, t, c, -1, 1, 0, out_v, in_v)
                + near(bmap, src, t, c, -1, -1, 0, out_v, in_v)
            )
            fxz = 0.25 * (
                near(bmap, src, t, c, 1, 0, 1, out_v, in_v)
                - near(bmap, src, t, c, 1, 0, -1, out_v, in_v)
                - near(bmap, src, t, c, -1, 0, 1, out_v, in_v)
                + near(bmap, src, t, c, -1, 0, -1, out_v, in_v)
            )
            fyz = 0.25 * (
                near(bmap, src, t, c, 0, 1, 1, out_v, in_v)
                - near(bmap, src, t, c, 0, 1, -1, out_v, in_v)
                - near(bmap, src, t, c, 0, -1, 1, out_v, in_v)
                + near(bmap, src, t, c, 0, -1, -1, out_v, in_v)
            )
            dst[t] = edge_flow_step(
                p0,
                near(bmap, src, t, c, -1, 0, 0, out_v, in_v),
                near(bmap, src, t, c, 1, 0, 0, out_v, in_v),
                near(bmap, src, t, c, 0, -1, 0, out_v, in_v),
                near(bmap, src, t, c, 0, 1, 0, out_v, in_v),
                near(bmap, src, t, c, 0, 0, -1, out_v, in_v),
                near(bmap, src, t, c, 0, 0, 1, out_v, in_v),
                fxy,
                fxz,
                fyz,
                dt,
                taper,
                g8,
                pit,
            )
        q += 1


@wp.func
def flow_rows(src: wp.array(dtype=vec8), codes: vec27i, r0: int, r: int, c: vec8, out_v: float, in_v: float):
    """The neighbour values flow_step reads, for the 8 voxels of row r of the block whose rows
    start at r0 (c: the row itself): (x - 1, x + 1, y - 1, y + 1, z - 1, z + 1 rows, fxy, fxz,
    fyz), each the same float as voxels.get reads and combines per voxel."""
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
        fxy = 0.25 * (
            ext_row(src, codes, x + 1, y + 1, 0, out_v, in_v)
            - ext_row(src, codes, x + 1, y - 1, 0, out_v, in_v)
            - ext_row(src, codes, x - 1, y + 1, 0, out_v, in_v)
            + ext_row(src, codes, x - 1, y - 1, 0, out_v, in_v)
        )
    zm, zp = z_pair(src, codes, x, y, c, out_v, in_v)
    xm_down, xm_up = z_pair(src, codes, x - 1, y, xm, out_v, in_v)
    xp_down, xp_up = z_pair(src, codes, x + 1, y, xp, out_v, in_v)
    ym_down, ym_up = z_pair(src, codes, x, y - 1, ym, out_v, in_v)
    yp_down, yp_up = z_pair(src, codes, x, y + 1, yp, out_v, in_v)
    fxz = 0.25 * (xp_up - xp_down - xm_up + xm_down)
    fyz = 0.25 * (yp_up - yp_down - ym_up + ym_down)
    return xm, xp, ym, yp, zm, zp, fxy, fxz, fyz


@cpu_kernel
def curvature_flow_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=vec8),
    out_v: float,
    in_v: float,
    dt: float,
    band: float,
    dst: wp.array(dtype=vec8),
    base: int,
):
    """curvature_flow on one block (thread = block), a row of 8 voxels along z at
    a time: the 26 neighbour blocks are looked up once, a row's neighbour rows read once, and
    flow_step's arithmetic runs 8 voxels at a time, the same operations in the
    same order, so the results are the voxel kernel's bit for bit; rows with no value in the
    band are skipped. The voxels where the edge gate is open
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
        num = (
            wp.cw_mul(gxx, fxx)
            + wp.cw_mul(gyy, fyy)
            + wp.cw_mul(gzz, fzz)
            + 2.0
            * (
                wp.cw_mul(wp.cw_mul(gx, gy), fxy)
                + wp.cw_mul(wp.cw_mul(gx, gz), fxz)
                + wp.cw_mul(wp.cw_mul(gy, gz), fyz)
            )
        )
        lap = fxx + fyy + fzz
        out = vec8()
        for k in range(BS):
            taper = flow_taper(c[k], band)
            nhn = float(0.0)
            if g2[k] > 1.0e-8:
                nhn = num[k] / g2[k]
            out[k] = wp.where(taper == 0.0, c[k], c[k] + taper * dt * (lap[k] - nhn))
        dst[r0 + r] = out


@cpu_kernel
def edge_flow_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=vec8),
    out_v: float,
    in_v: float,
    dt: float,
    band: float,
    gate: wp.array(dtype=float),
    pit: float,
    dst: wp.array(dtype=vec8),
    base: int,
):
    """edge_flow after curvature_flow_lines (thread = block): the rows that cross
    an open gate cell read their neighbour rows as curvature_flow_lines does (flow_rows), and
    their voxels in an open cell take edge_flow_step, the same values in the
    same operations as the voxel kernel. Kept out of the row kernel: there the edge step's
    code, even in a branch never taken, would make the flow twice as slow. Rows, not a voxel
    per neighbour read (`get`): a splash has open gates all over."""
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
                    out[k] = edge_flow_step(
                        c[k], xm[k], xp[k], ym[k], yp[k], zm[k], zp[k], fxy[k], fxz[k], fyz[k], dt, taper, g8, pit
                    )
                k += 1
            dst[r0 + r] = out


@cpu_kernel
def limit_inward_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    a: wp.array(dtype=vec8),
    ref: wp.array(dtype=vec8),
    full: float,
    gate: wp.array(dtype=float),
    noise: wp.array(dtype=float),
    base: int,
):
    """limit_inward for the 64 rows of active block b (thread = block; bcoord
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


def smooth_by_voxel(bcoord, bmap, dist, iters: int, tiles, *, limit: float, edges: tuple):
    """`iters` steps of the level set's mean-curvature flow over the distance `dist` (kept;
    curvature_flow, FLOW_DT voxel^2 a step, values within FLOW_BAND of the zero level), the
    surface then moved at most `limit` voxels inward, and at an edge at most EDGE_NOISE x the
    noise of its samples (`edges`: mpmfx.surface.edges' gate and noise; on a lattice the raw
    field already holds an edge, and the flow would only round it). A voxel or a line per thread.
    The flow averages the surface's noise on random samples away, as a [1 2 1]/4 blur along each
    axis would, but only along the surface: the blur's Laplacian also averages across it, so it
    eats into anything thinner than it is wide, and pinches the gaps of a random sheet into
    holes. The limit keeps the flow from shrinking a drop or a filament away (half thickness
    ~r). Outward it is free: that is how the dents of sample voids fill."""
    gate, noise, _ = edges if edges is not None else (None, None, None)

    def step(phi, tmp):  # a line each
        split(wp, curvature_flow, phi.shape[0] // BS, [bcoord, bmap, phi, *tiles, FLOW_DT, FLOW_BAND, tmp])
        split(wp, edge_flow, gate.shape[0], [bcoord, bmap, phi, *tiles, FLOW_DT, FLOW_BAND, gate, EDGE_PIT, tmp])

    def bound(phi):
        split(wp, limit_inward, phi.shape[0], [phi, dist, limit, gate, noise])

    return _flow(dist, iters, step, bound)


def smooth_by_block(bcoord, bmap, dist, iters: int, tiles, *, limit: float, edges: tuple):
    """smooth_by_voxel, a block per thread in rows of 8."""
    gate, noise, _ = edges if edges is not None else (None, None, None)

    def step(phi, tmp):
        launch_blocks(wp, curvature_flow_lines, [bcoord, bmap, rows(phi), *tiles, FLOW_DT, FLOW_BAND, rows(tmp)])
        launch_blocks(
            wp, edge_flow_lines, [bcoord, bmap, rows(phi), *tiles, FLOW_DT, FLOW_BAND, gate, EDGE_PIT, rows(tmp)]
        )

    def bound(phi):
        launch_blocks(wp, limit_inward_lines, [bcoord, rows(phi), rows(dist), limit, gate, noise])

    return _flow(dist, iters, step, bound)


def _flow(dist, iters: int, step, bound):
    if iters == 0 or dist.shape[0] == 0:  # no active voxel: no edges measured either
        return dist
    phi, tmp = (
        dist,
        wp.empty_like(dist),
    )  # the first step reads dist itself (kept: no copy), then two buffers take turns
    for _ in range(iters):
        step(phi, tmp)
        phi, tmp = tmp, (wp.empty_like(dist) if phi is dist else phi)
    bound(phi)
    return phi
