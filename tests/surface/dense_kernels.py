"""Warp kernels of the dense reference surfacer (tests/surface/dense_reference.py): one module,
so Warp compiles it once per device.

Grid convention: node (i, j, k) of every 3-D array sits at world origin + (i, j, k) * voxel;
"grid coordinates" g = (x - origin) / voxel are in voxel units.
"""

import warp as wp

LABEL_NONE = wp.constant(-1)  # voxel outside the region being labelled
LABEL_BIG = wp.constant(2147483647)  # region voxel not (yet) reached by any seed

# The flood fill's line sweep is the product's (the same kernel over any 3-D label grid, the same labels).
from mpmfx.surface.classify import sweep_block_labels as sweep_labels  # noqa: E402,F401

# ... and the smoothing's arithmetic (the dense grid reads its neighbours its own way)
from mpmfx.surface.smooth import flow_step, flow_taper  # noqa: E402


@wp.func
def zb_weight(s2: float):
    # Zhu & Bridson 2005, eq. 3: k(s) = max(0, 1 - s^2)^3 with s = |x - x_i| / R.
    t = 1.0 - s2
    return t * t * t


@wp.kernel
def splat_zhu_bridson(
    g: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    with_v: int,
    reach: float,
    w_grid: wp.array3d(dtype=float),
    gw_grid: wp.array3d(dtype=wp.vec3),
    vw_grid: wp.array3d(dtype=wp.vec3),
):
    """Scatter kernel weights w, w * g and w * v of one particle to nodes within `reach` voxels."""
    p = wp.tid()
    gp = g[p]
    r2 = reach * reach
    i0 = wp.max(int(wp.ceil(gp[0] - reach)), 0)
    i1 = wp.min(int(wp.floor(gp[0] + reach)), w_grid.shape[0] - 1)
    j0 = wp.max(int(wp.ceil(gp[1] - reach)), 0)
    j1 = wp.min(int(wp.floor(gp[1] + reach)), w_grid.shape[1] - 1)
    k0 = wp.max(int(wp.ceil(gp[2] - reach)), 0)
    k1 = wp.min(int(wp.floor(gp[2] + reach)), w_grid.shape[2] - 1)
    for i in range(i0, i1 + 1):
        dx = float(i) - gp[0]
        for j in range(j0, j1 + 1):
            dy = float(j) - gp[1]
            dxy2 = dx * dx + dy * dy
            if dxy2 < r2:
                for k in range(k0, k1 + 1):
                    dz = float(k) - gp[2]
                    d2 = dxy2 + dz * dz
                    if d2 < r2:
                        w = zb_weight(d2 / r2)
                        wp.atomic_add(w_grid, i, j, k, w)
                        wp.atomic_add(gw_grid, i, j, k, w * gp)
                        if with_v != 0:
                            wp.atomic_add(vw_grid, i, j, k, w * v[p])


@wp.kernel
def zhu_bridson_phi(
    w_grid: wp.array3d(dtype=float),
    wn_grid: wp.array3d(dtype=float),
    gw_grid: wp.array3d(dtype=wp.vec3),
    radius_vox: float,
    far_vox: float,
    projected: int,
    phi: wp.array3d(dtype=float),
):
    """phi = |g - gbar| - r in voxel units; `far_vox` where no particle reaches.
    wn_grid: the weights whose gradient gives the normal (w_grid blurred wider, or w_grid).

    With `projected`, g - gbar is projected on the outward normal -grad(w)/|grad(w)|: on
    irregular (random) samples gbar jitters sideways as much as along the normal, and
    |g - gbar| turns that sideways jitter into an outward bias (the surface shrinks by
    ~0.3 particle spacings); the projection keeps only the normal part. On a flat or
    spherical boundary g - gbar is already normal, so the two agree there.
    """
    i, j, k = wp.tid()
    w = w_grid[i, j, k]
    if w <= 0.0:
        phi[i, j, k] = far_vox
        return
    d = wp.vec3(float(i), float(j), float(k)) - gw_grid[i, j, k] / w
    dist = wp.length(d)
    if projected != 0:
        nx = w_grid.shape[0] - 1
        ny = w_grid.shape[1] - 1
        nz = w_grid.shape[2] - 1
        grad = wp.vec3(
            wn_grid[wp.min(i + 1, nx), j, k] - wn_grid[wp.max(i - 1, 0), j, k],
            wn_grid[i, wp.min(j + 1, ny), k] - wn_grid[i, wp.max(j - 1, 0), k],
            wn_grid[i, j, wp.min(k + 1, nz)] - wn_grid[i, j, wp.max(k - 1, 0)],
        )
        gl = wp.length(grad)
        if gl > 0.0:
            dist = -wp.dot(d, grad) / gl
    phi[i, j, k] = dist - radius_vox


@wp.kernel
def splat_spheres(g: wp.array(dtype=wp.vec3), radius_vox: float, reach: float, phi: wp.array3d(dtype=float)):
    """phi = min over particles of |g - g_p| - r (voxel units), within `reach` voxels of each."""
    p = wp.tid()
    gp = g[p]
    i0 = wp.max(int(wp.ceil(gp[0] - reach)), 0)
    i1 = wp.min(int(wp.floor(gp[0] + reach)), phi.shape[0] - 1)
    j0 = wp.max(int(wp.ceil(gp[1] - reach)), 0)
    j1 = wp.min(int(wp.floor(gp[1] + reach)), phi.shape[1] - 1)
    k0 = wp.max(int(wp.ceil(gp[2] - reach)), 0)
    k1 = wp.min(int(wp.floor(gp[2] + reach)), phi.shape[2] - 1)
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            for k in range(k0, k1 + 1):
                d = wp.length(wp.vec3(float(i), float(j), float(k)) - gp)
                if d < reach:
                    wp.atomic_min(phi, i, j, k, d - radius_vox)


@wp.kernel
def fill_float(a: wp.array3d(dtype=float), value: float):
    i, j, k = wp.tid()
    a[i, j, k] = value


@wp.kernel
def add_float(a: wp.array3d(dtype=float), value: float):
    i, j, k = wp.tid()
    a[i, j, k] = a[i, j, k] + value


@wp.func
def axis_offset(axis: int, s: int):
    if axis == 0:
        return wp.vec3i(s, 0, 0)
    if axis == 1:
        return wp.vec3i(0, s, 0)
    return wp.vec3i(0, 0, s)


@wp.kernel
def curvature_flow(src: wp.array3d(dtype=float), dt: float, band: float, dst: wp.array3d(dtype=float)):
    """mpmfx.surface.smooth.curvature_flow on the dense grid (edge values repeated)."""
    i, j, k = wp.tid()
    p0 = src[i, j, k]
    taper = flow_taper(p0, band)
    if taper == 0.0:
        dst[i, j, k] = p0
        return
    nx = src.shape[0] - 1
    ny = src.shape[1] - 1
    nz = src.shape[2] - 1
    im = wp.max(i - 1, 0)
    ip = wp.min(i + 1, nx)
    jm = wp.max(j - 1, 0)
    jp = wp.min(j + 1, ny)
    km = wp.max(k - 1, 0)
    kp = wp.min(k + 1, nz)
    xm = src[im, j, k]
    xp = src[ip, j, k]
    ym = src[i, jm, k]
    yp = src[i, jp, k]
    zm = src[i, j, km]
    zp = src[i, j, kp]
    fxy = 0.25 * (src[ip, jp, k] - src[ip, jm, k] - src[im, jp, k] + src[im, jm, k])
    fxz = 0.25 * (src[ip, j, kp] - src[ip, j, km] - src[im, j, kp] + src[im, j, km])
    fyz = 0.25 * (src[i, jp, kp] - src[i, jp, km] - src[i, jm, kp] + src[i, jm, km])
    dst[i, j, k] = flow_step(p0, xm, xp, ym, yp, zm, zp, fxy, fxz, fyz, dt, taper)


@wp.kernel
def blur_axis_step(src: wp.array3d(dtype=float), axis: int, step: int, dst: wp.array3d(dtype=float)):
    """dst = [1 2 1]/4 blur of src along `axis` with taps `step` voxels apart (edges repeated)."""
    i, j, k = wp.tid()
    n = src.shape[axis]
    c = wp.vec3i(i, j, k)
    lo = wp.vec3i(i, j, k)
    hi = wp.vec3i(i, j, k)
    lo[axis] = wp.max(c[axis] - step, 0)
    hi[axis] = wp.min(c[axis] + step, n - 1)
    dst[i, j, k] = 0.25 * src[lo[0], lo[1], lo[2]] + 0.5 * src[i, j, k] + 0.25 * src[hi[0], hi[1], hi[2]]


@wp.kernel
def average_into(a: wp.array3d(dtype=float), b: wp.array3d(dtype=float)):
    i, j, k = wp.tid()
    a[i, j, k] = 0.5 * (a[i, j, k] + b[i, j, k])


@wp.kernel
def init_outside_labels(phi: wp.array3d(dtype=float), labels: wp.array3d(dtype=wp.int32)):
    """Region = phi > 0; seeds (label 0) are region voxels on the grid's outer faces."""
    i, j, k = wp.tid()
    if phi[i, j, k] > 0.0:
        nx = phi.shape[0] - 1
        ny = phi.shape[1] - 1
        nz = phi.shape[2] - 1
        if i == 0 or j == 0 or k == 0 or i == nx or j == ny or k == nz:
            labels[i, j, k] = 0
        else:
            labels[i, j, k] = LABEL_BIG
    else:
        labels[i, j, k] = LABEL_NONE


@wp.kernel
def init_inside_labels(phi: wp.array3d(dtype=float), labels: wp.array3d(dtype=wp.int32)):
    """Region = phi < 0; every region voxel seeds its own label (its linear index)."""
    i, j, k = wp.tid()
    if phi[i, j, k] < 0.0:
        labels[i, j, k] = (i * phi.shape[1] + j) * phi.shape[2] + k
    else:
        labels[i, j, k] = LABEL_NONE


@wp.kernel
def fill_unreached(phi: wp.array3d(dtype=float), labels: wp.array3d(dtype=wp.int32), inside_value: float):
    """Outside voxels that no path from the grid boundary reaches are bubbles: make them inside."""
    i, j, k = wp.tid()
    if labels[i, j, k] > 0:
        phi[i, j, k] = inside_value


@wp.kernel
def renormalise(phi: wp.array3d(dtype=float), voxel: float, background: float, out: wp.array3d(dtype=float)):
    """out = clip(phi / |grad phi|, +-background) * voxel: a signed distance near the zero level.

    The raw field keeps its sign (so its zero level) but its slope is not 1 (Zhu-Bridson is
    ~0.7 at the surface and 0 deep inside); dividing by the central-difference gradient
    restores world-unit distances in the band, clipping handles the flat interior.
    """
    i, j, k = wp.tid()
    nx = phi.shape[0] - 1
    ny = phi.shape[1] - 1
    nz = phi.shape[2] - 1
    gx = phi[wp.min(i + 1, nx), j, k] - phi[wp.max(i - 1, 0), j, k]
    gy = phi[i, wp.min(j + 1, ny), k] - phi[i, wp.max(j - 1, 0), k]
    gz = phi[i, j, wp.min(k + 1, nz)] - phi[i, j, wp.max(k - 1, 0)]
    grad = 0.5 * wp.length(wp.vec3(gx, gy, gz))
    d = phi[i, j, k] / wp.max(grad, 0.05) * voxel
    out[i, j, k] = wp.clamp(d, -background, background)


@wp.kernel
def normalise_velocity(
    w_grid: wp.array3d(dtype=float), vw_grid: wp.array3d(dtype=wp.vec3), vel: wp.array3d(dtype=wp.vec3)
):
    i, j, k = wp.tid()
    w = w_grid[i, j, k]
    if w > 0.0:
        vel[i, j, k] = vw_grid[i, j, k] / w
    else:
        vel[i, j, k] = wp.vec3(0.0)


@wp.func
def trilinear_corners(g: wp.vec3, shape: wp.vec3i):
    # Lower corner index (clamped so the cell stays inside the grid) and fractional offset.
    c = wp.vec3i(0)
    f = wp.vec3(0.0)
    for a in range(3):
        ia = wp.clamp(int(wp.floor(g[a])), 0, shape[a] - 2)
        c[a] = ia
        f[a] = wp.clamp(g[a] - float(ia), 0.0, 1.0)
    return c, f


@wp.kernel
def sample_vertices(
    verts: wp.array(dtype=wp.vec3),
    origin: wp.vec3,
    inv_voxel: float,
    phi: wp.array3d(dtype=float),
    vel: wp.array3d(dtype=wp.vec3),
    with_v: int,
    normals: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
):
    """Outward normal (trilinear gradient of phi) and trilinear velocity at each vertex."""
    t = wp.tid()
    g = (verts[t] - origin) * inv_voxel
    shape = wp.vec3i(phi.shape[0], phi.shape[1], phi.shape[2])
    c, f = trilinear_corners(g, shape)
    grad = wp.vec3(0.0)
    vv = wp.vec3(0.0)
    for corner in range(8):
        ox = corner & 1
        oy = (corner >> 1) & 1
        oz = (corner >> 2) & 1
        wx = wp.where(ox == 1, f[0], 1.0 - f[0])
        wy = wp.where(oy == 1, f[1], 1.0 - f[1])
        wz = wp.where(oz == 1, f[2], 1.0 - f[2])
        val = phi[c[0] + ox, c[1] + oy, c[2] + oz]
        # d/dx of the trilinear weight wx*wy*wz is (+-1)*wy*wz
        sx = wp.where(ox == 1, 1.0, -1.0)
        sy = wp.where(oy == 1, 1.0, -1.0)
        sz = wp.where(oz == 1, 1.0, -1.0)
        grad += val * wp.vec3(sx * wy * wz, sy * wx * wz, sz * wx * wy)
        if with_v != 0:
            vv += (wx * wy * wz) * vel[c[0] + ox, c[1] + oy, c[2] + oz]
    ln = wp.length(grad)
    if ln > 0.0:
        normals[t] = grad / ln
    else:
        normals[t] = wp.vec3(0.0, 0.0, 1.0)
    velocities[t] = vv


@wp.kernel
def particle_labels(g: wp.array(dtype=wp.vec3), labels: wp.array3d(dtype=wp.int32), out: wp.array(dtype=wp.int32)):
    """Label of the voxel nearest to each particle (LABEL_NONE when outside the surface)."""
    p = wp.tid()
    gp = g[p]
    i = wp.clamp(int(wp.round(gp[0])), 0, labels.shape[0] - 1)
    j = wp.clamp(int(wp.round(gp[1])), 0, labels.shape[1] - 1)
    k = wp.clamp(int(wp.round(gp[2])), 0, labels.shape[2] - 1)
    out[p] = labels[i, j, k]


@wp.kernel
def count_particles(labels: wp.array(dtype=wp.int32), counts: wp.array(dtype=wp.int32)):
    """counts[label] += 1 per particle; labels are linear voxel indices of component roots."""
    p = wp.tid()
    lab = labels[p]
    if lab >= 0:
        wp.atomic_add(counts, lab, 1)


@wp.kernel
def remove_small(
    labels: wp.array3d(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    min_count: int,
    far_value: float,
    phi: wp.array3d(dtype=float),
):
    """Voxels of components holding fewer than `min_count` particles become outside."""
    i, j, k = wp.tid()
    lab = labels[i, j, k]
    if lab >= 0:
        if counts[lab] < min_count:
            phi[i, j, k] = far_value
