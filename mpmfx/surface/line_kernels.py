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

from mpmfx.surface.sparse_kernels import BS, CS, write_field

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
