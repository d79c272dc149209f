"""Warp kernels that turn a level set into a signed distance over the narrow band (grid units).

The Zhu-Bridson field is a distance only near its zero level (it flattens to -r inside), so
blurring it moved curved surfaces outward once the blur reached the flat part. Here the
voxels next to the zero crossing keep their first-order distance, and the rest of the band is
filled by Jacobi sweeps of the Eikonal equation |grad phi| = 1 (the fast iterative method,
upwind, one voxel of progress per sweep), so the smoothing that follows sees a true distance.
"""

import warp as wp

from mpmfx.surface.sparse_kernels import BS, BV, line_value, line_z, side_line, step_get, voxel_of


@wp.func
def crossing_fraction(v: float, u: float):
    """|v| / (|v| + |u|): the fraction of the way from v to the zero crossing interpolated
    towards its neighbour u, where u has the other sign; 2 (none) where it has v's."""
    f = float(2.0)
    if (u > 0.0) != (v > 0.0):
        f = wp.abs(v) / wp.max(wp.abs(v) + wp.abs(u), 1.0e-12)
    return f


@wp.func
def axis_inv2(v: float, u: float, inv2: float):
    """max(inv2, 1 / t^2), t = v / (v - u) the zero level's distance from v along the axis
    towards its neighbour u by linear interpolation (t <= 1: u has the other sign) or
    extrapolation (t > 1: u has v's sign but is nearer zero); inv2 where the line moves away
    from zero. 1 / t^2 is continuous as u passes through zero, so the plane start does not jump
    when a crossing appears on another axis between frames."""
    out = inv2
    if (u > 0.0) != (v > 0.0):
        f = wp.abs(v) / wp.max(wp.abs(v) + wp.abs(u), 1.0e-12)
        out = wp.max(inv2, 1.0 / wp.max(f * f, 1.0e-24))
    elif wp.abs(u) < wp.abs(v):
        g = (wp.abs(v) - wp.abs(u)) / wp.abs(v)
        out = wp.max(inv2, g * g)
    return out


@wp.func
def frozen_distance(v: float, inv2: wp.vec3, near: float, plane: int):
    """The start value (v's sign) of a voxel next to the zero crossing. plane != 0: its distance
    to the plane through the crossings interpolated along each axis (inv2[a] = 1 / the nearest
    one's fraction^2 along axis a: axis_inv2), 1 / sqrt(sum inv2): slope 1 across the crossing
    whatever the field's slope there, the crossings where linear interpolation puts them on an
    axis-aligned face. plane = 0: |v|, at most the nearest axis crossing `near` (for a field
    that is a distance already: the closing's grown one)."""
    d = wp.min(wp.abs(v), near)
    if plane != 0:
        d = 1.0 / wp.sqrt(inv2[0] + inv2[1] + inv2[2])
    return wp.where(v > 0.0, d, -d)


@wp.kernel
def init_eikonal(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    clip: float,
    plane: int,
    frozen: wp.array(dtype=wp.int32),
    dist: wp.array(dtype=float),
    base: int,
):
    """Voxels with a 6-neighbour of the other sign (frozen = 1) start at frozen_distance; the
    others at +-clip with phi's sign. With plane = 1 (the raw field, sparse._distance) that is
    the distance to the plane through the axis crossings; it used to be phi itself (at most the
    nearest axis crossing), but the raw field's slope across its crossing is not 1 (0.97 on a
    flat lattice face: -0.008 / +0.964 voxels), so the distance had a kink there, and each blur
    pass moved flat faces out across it (+0.014 h after five passes on the 100k lattice box,
    "fine"). plane = 0 keeps phi (the closing's grown distance: redistancing it then changes
    nothing on a smooth surface, and the closing's gate leaves lattices where they were)."""
    t = wp.tid() + base
    c = voxel_of(t, bcoord)
    v = phi[t]
    inv2 = wp.vec3(0.0)
    near = float(1.0)
    cross = int(0)
    for n in range(6):
        u = step_get(bmap, phi, t, c, n // 2, 2 * (n % 2) - 1, out_v, in_v)
        f = crossing_fraction(v, u)
        if f <= 1.0:
            cross = 1
            near = wp.min(near, f)
        inv2[n // 2] = axis_inv2(v, u, inv2[n // 2])
    frozen[t] = cross
    if cross == 1:
        dist[t] = frozen_distance(v, inv2, near, plane)
    else:
        dist[t] = wp.where(v > 0.0, clip, -clip)


@wp.kernel
def eikonal_sweep(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=float),
    frozen: wp.array(dtype=wp.int32),
    out_v: float,
    in_v: float,
    clip: float,
    dst: wp.array(dtype=float),
    base: int,
):
    """One Jacobi sweep of |grad phi| = 1 (upwind, unit spacing) on |phi|, keeping each sign, on
    the 8 voxels of one line along z (thread = line, 64 a block): the neighbour lines and the
    blocks below and above are found once for the line, not at every voxel on a block face
    (each voxel gets what a voxel per thread with step_get did, bit for bit)."""
    q = wp.tid() + base
    b = q // 64
    l = q - b * 64
    x = l // BS
    y = l - x * BS
    bc = bcoord[b]
    t0 = b * BV + l * BS
    xm = side_line(bmap, bc, b, x - 1, y, 0)
    xp = side_line(bmap, bc, b, x + 1, y, 0)
    ym = side_line(bmap, bc, b, x, y - 1, 0)
    yp = side_line(bmap, bc, b, x, y + 1, 0)
    zm = side_line(bmap, bc, b, x, y, -1)
    zp = side_line(bmap, bc, b, x, y, 1)
    for k in range(BS):
        t = t0 + k
        v = src[t]
        if frozen[t] != 0:
            dst[t] = v
            continue
        a = wp.vec3(wp.min(wp.abs(line_value(src, xm, k, out_v, in_v)), wp.abs(line_value(src, xp, k, out_v, in_v))),
                    wp.min(wp.abs(line_value(src, ym, k, out_v, in_v)), wp.abs(line_value(src, yp, k, out_v, in_v))),
                    wp.min(wp.abs(line_z(src, t0, zm, zp, k - 1, out_v, in_v)), wp.abs(line_z(src, t0, zm, zp, k + 1, out_v, in_v))))
        dst[t] = eikonal_update(a, v, clip)


@wp.func
def eikonal_update(a: wp.vec3, v: float, clip: float):
    """The upwind solution of |grad u| = 1 from the smaller neighbour magnitude per axis `a`,
    at most |v| and clip, with v's sign."""
    # sort a[0] <= a[1] <= a[2]
    a0 = wp.min(a[0], wp.min(a[1], a[2]))
    a2 = wp.max(a[0], wp.max(a[1], a[2]))
    a1 = a[0] + a[1] + a[2] - a0 - a2
    u = a0 + 1.0
    if u > a1:
        u = 0.5 * (a0 + a1 + wp.sqrt(wp.max(2.0 - (a0 - a1) * (a0 - a1), 0.0)))
        if u > a2:
            s = a0 + a1 + a2
            u = (s + wp.sqrt(wp.max(s * s - 3.0 * (a0 * a0 + a1 * a1 + a2 * a2 - 1.0), 0.0))) / 3.0
    u = wp.min(wp.min(u, wp.abs(v)), clip)
    return wp.where(v > 0.0, u, -u)
