"""Warp kernels of the anisotropic surfacer (`SurfaceParams.anisotropic`): particle shapes and
the field gather with them.

Yu, J. and Turk, G., "Reconstructing surfaces of particle-based fluids using anisotropic
kernels", ACM TOG 32(1), 2013: per particle, the principal axes of its neighbours' weighted
covariance stretch its kernel into an ellipsoid, long along a sheet or surface and short
across it, so a one-particle-thick sheet stays a sheet. (Their "x-bar" step, moving each
particle towards its neighbours' mean, is left out: on random samples it makes the surface
noisier and shrinks it by a few percent in volume.)

Units: grid (voxel) coordinates throughout, as in :mod:`mpmfx.surface.voxels`.
"""

import warp as wp

from mpmfx.surface.gather import cell_range, column_slots, write_field
from mpmfx.surface.voxels import voxel_of

# forward only: nothing differentiates these kernels; their adjoint code would only lengthen the compile
wp.set_module_options({"enable_backward": False})


@wp.kernel
def particle_shape(
    gs: wp.array(dtype=wp.vec3),
    cells: wp.array3d(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    reach: float,
    max_ratio: float,
    max_stretch: float,
    min_neighbours: int,
    gmat: wp.array(dtype=wp.mat33),
    thin: wp.array(dtype=float),
):
    """gmat[p] maps an offset from particle p (voxels; gs, the particles in the cells' order) to its kernel's unit ball: I / reach for
    fewer than min_neighbours neighbours within `reach` voxels (spray stays round), else
    Q diag(1 / (reach a_i)) Q^T with Q the principal axes of the neighbours' covariance (weights
    (1 - d^2/reach^2)^3) and a_i their standard deviations, the smallest raised to the largest /
    max_ratio, scaled to a_1 a_2 a_3 = 1 (the ellipsoid keeps the ball's volume), each at most
    max_stretch. thin = the shortest a_i (1 when round)."""
    p = wp.tid()
    x = gs[p]
    r2 = reach * reach
    lo, hi = cell_range(x, reach, wp.vec3i(cells.shape[0], cells.shape[1], cells.shape[2]))
    w = float(0.0)
    m = wp.vec3(0.0)
    c = wp.mat33(0.0)
    count = int(0)
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
                    m += wk * d
                    c += wk * wp.outer(d, d)
                    count += 1
                q += 1
    m = m / w  # w > 0: the particle itself counts
    iso = wp.identity(n=3, dtype=float) / reach
    thin[p] = 1.0
    if count < min_neighbours:
        gmat[p] = iso
        return
    cov = c / w - wp.outer(m, m)
    Q, ev = wp.eig3(cov)
    sd = wp.vec3(wp.sqrt(wp.max(ev[0], 0.0)), wp.sqrt(wp.max(ev[1], 0.0)), wp.sqrt(wp.max(ev[2], 0.0)))
    top = wp.max(sd[0], wp.max(sd[1], sd[2]))
    if top <= 0.0:
        gmat[p] = iso
        return
    for a in range(3):
        sd[a] = wp.max(sd[a], top / max_ratio)
    geo = wp.pow(sd[0] * sd[1] * sd[2], 1.0 / 3.0)
    inv = wp.vec3(0.0)
    shortest = float(max_stretch)
    for a in range(3):
        stretch = wp.min(sd[a] / geo, max_stretch)
        inv[a] = 1.0 / (reach * stretch)
        shortest = wp.min(shortest, stretch)
    gmat[p] = Q * wp.diag(inv) * wp.transpose(Q)
    thin[p] = shortest


@wp.kernel
def gather_zhu_bridson_aniso(
    bcoord: wp.array(dtype=wp.vec3i),
    cells: wp.array3d(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    gs: wp.array(dtype=wp.vec3),
    gmat: wp.array(dtype=wp.mat33),
    thin: wp.array(dtype=float),
    vs: wp.array(dtype=wp.vec3),
    with_v: int,
    reach: float,
    kernel_vox: float,
    radius_vox: float,
    far_vox: float,
    phi: wp.array(dtype=float),
    w_out: wp.array(dtype=float),
    offset: wp.array(dtype=wp.vec3),
    vel: wp.array(dtype=wp.vec3),
    cov: wp.array(dtype=wp.mat33),
    offset_r: wp.array(dtype=float),
):
    """:func:`mpmfx.surface.gather.gather_zhu_bridson` with each particle's own ellipsoid:
    weight (1 - |G_p (x_p - x)|^2)^3 det(G_p) kernel_vox^3 (G_p = gmat[p], the det keeps every
    particle's weight integral that of the isotropic kernel); `reach` (voxels) bounds the
    longest ellipsoid axis. Also the neighbours' weighted covariance `cov` (voxels^2, for the
    normal: field.project_on_wide_normal) and the voxel's particle radius `offset_r`
    (voxels): r x (1 + mean shortest axis) / 2. The centroid of kernels that are short across
    a sheet sits nearer the voxel, so the full r would make the bench's random sheet 1.9 h
    thick instead of h, and r x the mean shortest axis would open holes and erase the lattice
    sheet; the midway value keeps both closed."""
    t = wp.tid()
    c = voxel_of(t, bcoord)
    x = wp.vec3(float(c[0]), float(c[1]), float(c[2]))
    r2 = reach * reach
    lo, hi = cell_range(x, reach, wp.vec3i(cells.shape[0], cells.shape[1], cells.shape[2]))
    k3 = kernel_vox * kernel_vox * kernel_vox
    w = float(0.0)
    dw = wp.vec3(0.0)
    gw = wp.vec3(0.0)
    vw = wp.vec3(0.0)
    cw = wp.mat33(0.0)
    tw = float(0.0)
    for bi in range(lo[0], hi[0] + 1):
        for bj in range(lo[1], hi[1] + 1):
            q, end = column_slots(x, r2, bi, bj, lo[2], hi[2], cells, starts)
            while q < end:
                d = gs[q] - x
                if wp.dot(d, d) < r2:
                    G = gmat[q]
                    e = G * d
                    s2 = wp.dot(e, e)
                    if s2 < 1.0:
                        u = 1.0 - s2
                        scale = wp.determinant(G) * k3
                        wk = u * u * u * scale
                        w += wk
                        dw += wk * d
                        gw += (u * u * scale * kernel_vox * kernel_vox) * (wp.transpose(G) * e)
                        cw += wk * wp.outer(d, d)
                        tw += wk * thin[q]
                        if with_v != 0:
                            vw += wk * vs[q]
                q += 1
    radius = radius_vox
    cov[t] = wp.mat33(0.0)
    if w > 0.0:
        m = dw / w
        cov[t] = cw / w - wp.outer(m, m)
        # the centroid of short kernels sits nearer the voxel: r shrinks with them
        radius = radius_vox * 0.5 * (1.0 + tw / w)
        offset_r[t] = radius
    write_field(t, w, dw, gw, vw, radius, with_v, far_vox, phi, w_out, offset, vel)
