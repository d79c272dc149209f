"""The faces' tangent planes of the sharpening pass (sharpen.py): the smoothed field sampled
between voxels (trilinear, onto_surface, unit_normal), the cells near the zero level flagged
(flag_cells), each flagged cell's planes fitted from pairs of points along the surface
(cell_planes), and a neighbourhood's planes read and merged (plane_cell, merge_planes). Lengths
are voxels; a cell is 2^3 voxels (voxels.gate_cell)."""

import warp as wp

from mpmfx.surface.voxels import BS, BV, gate_cell, get, slot

# forward only: nothing differentiates these kernels; their adjoint code would only lengthen the compile
wp.set_module_options({"enable_backward": False})

# directions around a cell's normal that look for a face: each face's normal is a mean over the
# directions that found it, and at 8 it turned enough from frame to frame to move a crest 5-10
# voxels from its points (the gliding block's vertices p99 0.080 h off the previous frame, 0.038
# with the exact normals; 16: 0.055, with the side normals too 0.049)
DIRECTIONS = wp.constant(16)
CELL_PLANES = wp.constant(3)  # planes a cell keeps (a corner's three faces)
NEAR_PLANES = wp.constant(4)  # planes a cell's neighbourhood may hold


@wp.func
def trilinear(bmap: wp.array3d(dtype=wp.int32), phi: wp.array(dtype=float), q: wp.vec3, out_v: float, in_v: float):
    """(value, gradient) of the trilinear interpolant of phi at q (voxel coordinates)."""
    i = int(wp.floor(q[0]))
    j = int(wp.floor(q[1]))
    k = int(wp.floor(q[2]))
    x = q[0] - float(i)
    y = q[1] - float(j)
    z = q[2] - float(k)
    c000 = get(bmap, phi, i, j, k, out_v, in_v)
    c001 = get(bmap, phi, i, j, k + 1, out_v, in_v)
    c010 = get(bmap, phi, i, j + 1, k, out_v, in_v)
    c011 = get(bmap, phi, i, j + 1, k + 1, out_v, in_v)
    c100 = get(bmap, phi, i + 1, j, k, out_v, in_v)
    c101 = get(bmap, phi, i + 1, j, k + 1, out_v, in_v)
    c110 = get(bmap, phi, i + 1, j + 1, k, out_v, in_v)
    c111 = get(bmap, phi, i + 1, j + 1, k + 1, out_v, in_v)
    c00 = c000 + (c001 - c000) * z
    c01 = c010 + (c011 - c010) * z
    c10 = c100 + (c101 - c100) * z
    c11 = c110 + (c111 - c110) * z
    c0 = c00 + (c01 - c00) * y
    c1 = c10 + (c11 - c10) * y
    d0 = (c001 - c000) + ((c011 - c010) - (c001 - c000)) * y
    d1 = (c101 - c100) + ((c111 - c110) - (c101 - c100)) * y
    g = wp.vec3(c1 - c0, (c01 - c00) + ((c11 - c10) - (c01 - c00)) * x, d0 + (d1 - d0) * x)
    return c0 + (c1 - c0) * x, g


@wp.func
def onto_surface(bmap: wp.array3d(dtype=wp.int32), phi: wp.array(dtype=float), q: wp.vec3, out_v: float, in_v: float):
    """q moved onto the zero level by three Newton steps along the gradient."""
    for _ in range(3):
        f, g = trilinear(bmap, phi, q, out_v, in_v)
        q = q - g * (f / wp.max(wp.dot(g, g), 1.0e-6))
    return q


@wp.func
def unit_normal(bmap: wp.array3d(dtype=wp.int32), phi: wp.array(dtype=float), q: wp.vec3, out_v: float, in_v: float):
    f, g = trilinear(bmap, phi, q, out_v, in_v)
    return wp.normalize(g)


@wp.func
def flat_beside(
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    q: wp.vec3,
    n: wp.vec3,
    d: wp.vec3,
    width: float,
    cos_flat: float,
    out_v: float,
    in_v: float,
):
    """The sum of the unit normals `width` to each side of q (across direction d) where they agree
    with n and with each other (a curve across d turns them apart by 2 width / its radius), else
    zero."""
    side = wp.normalize(wp.cross(d, n))
    a = unit_normal(bmap, phi, q + side * width, out_v, in_v)
    b = unit_normal(bmap, phi, q - side * width, out_v, in_v)
    if wp.dot(a, n) > cos_flat and wp.dot(b, n) > cos_flat and wp.dot(a, b) > cos_flat:
        return a + b
    return wp.vec3(0.0)


@wp.func
def cell_corner(bcoord: wp.array(dtype=wp.vec3i), u: int):
    """Global voxel of cell u's first (even) voxel."""
    c = u % 64
    return bcoord[u // 64] * BS + wp.vec3i((c // 16) * 2, ((c // 4) % 4) * 2, (c % 4) * 2)


@wp.func
def cell_at(bmap: wp.array3d(dtype=wp.int32), i: int, j: int, k: int):
    """Index of the 2^3-voxel cell holding voxel (i, j, k), or -1 outside the stored blocks."""
    t = slot(bmap, i, j, k)
    if t < 0:
        return -1
    l = t % BV
    return (t // BV) * 64 + gate_cell(0, l // 64, (l // 8) % 8, l % 8)


@wp.func
def plane_cell(
    bmap: wp.array3d(dtype=wp.int32),
    flags: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    e: wp.vec3i,
    di: int,
    dj: int,
    dk: int,
):
    """Slot of the cell (di, dj, dk) cells from the one at even voxel e where that cell is
    flagged, else -1."""
    v = cell_at(bmap, e[0] + 2 * di, e[1] + 2 * dj, e[2] + 2 * dk)
    if v < 0 or flags[v] == 0:
        return -1
    return slots[v]


@wp.func
def merge_planes(
    v: int,
    s: int,
    pn: wp.array(dtype=wp.vec3),
    pp: wp.array(dtype=wp.vec3),
    pw: wp.array(dtype=float),
    qn: wp.array(dtype=wp.vec3),
    qp: wp.array(dtype=wp.vec3),
    qw: wp.array(dtype=float),
    cos_same: float,
):
    """The planes cell slot v found merged into thread s's (the first it matches within
    cos_same, else the first free one; none where all NEAR_PLANES are taken)."""
    for m in range(CELL_PLANES):
        i = v * CELL_PLANES + m
        if pw[i] == 0.0:
            continue
        nk = wp.normalize(pn[i])
        for c in range(NEAR_PLANES):
            o = s * NEAR_PLANES + c
            if qw[o] == 0.0 or wp.dot(wp.normalize(qn[o]), nk) > cos_same:
                qn[o] = qn[o] + pn[i]
                qp[o] = qp[o] + pp[i]
                qw[o] = qw[o] + pw[i]
                break


@wp.kernel
def flag_cells(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    gate: wp.array(dtype=float),
    band: float,
    thin: float,
    flags: wp.array(dtype=wp.int32),
    base: int,
):
    """flags[u] = 1 where cell u's gate is open, its centre (the mean of its 8 voxels) lies
    within `band` of the zero level, and the body is thicker than `thin` there (the point that
    far under the surface along the normal is inside). A sheet's rim is its faces back to back,
    which no plane test keeps, and a thin sheet's gate is open all over: the random sheet's
    plane search and merge cost 80 ms of a 270 ms call at 20k on the CPU."""
    u = wp.tid() + base
    flags[u] = 0
    if gate[u] <= 0.0:
        return
    b = u // 64
    c = u - b * 64
    t = b * BV + ((c // 16) * 2 * BS + ((c // 4) % 4) * 2) * BS + (c % 4) * 2
    s = float(0.0)
    for q in range(8):
        s += phi[t + ((q // 4) * BS + (q // 2) % 2) * BS + q % 2]
    f = s * 0.125
    if wp.abs(f) >= band:
        return
    p = wp.vec3(cell_corner(bcoord, u)) + wp.vec3(0.5)
    n = unit_normal(bmap, phi, p, out_v, in_v)
    under, g = trilinear(bmap, phi, p - n * (f + thin), out_v, in_v)
    if under < 0.0:
        flags[u] = 1


@wp.kernel
def cell_planes(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    out_v: float,
    in_v: float,
    sample: wp.array(dtype=float),
    flags: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    near: float,
    far: float,
    width: float,
    cos_flat: float,
    plane_tol: float,
    cos_same: float,
    cells: wp.array(dtype=wp.int32),
    pn: wp.array(dtype=wp.vec3),
    pp: wp.array(dtype=wp.vec3),
    pw: wp.array(dtype=float),
    base: int,
):
    """For each flagged cell u (its slot s = slots[u]; cells[s] = u) whose cell coordinates are
    all even (one cell in 8: faces change over spacings, not from cell to cell) or that
    edge_gate saw as a corner (sample < 0; twice the directions there, its faces being narrower
    wedges): the faces around it, as up to CELL_PLANES planes (pn: summed unit normals, pp:
    summed points on the zero level, pw: how many directions found each). Along each direction
    d in the tangent plane at the cell's centre, the point `near` voxels out is moved onto the
    zero level, and from it the point `far` - `near` further along the surface; they make a
    plane where their normals agree within cos_flat, each lies within plane_tol of the other's
    tangent plane, and the normals `width` to either side of each agree too (a face, not a
    rounded crest or a curved body). Planes within cos_same of each other are one."""
    u = wp.tid() + base
    if flags[u] == 0:
        return
    s = slots[u]
    cells[s] = u
    for m in range(CELL_PLANES):
        pn[s * CELL_PLANES + m] = wp.vec3(0.0)
        pp[s * CELL_PLANES + m] = wp.vec3(0.0)
        pw[s * CELL_PLANES + m] = 0.0
    c = u % 64
    if ((c // 16) % 2 != 0 or ((c // 4) % 4) % 2 != 0 or (c % 4) % 2 != 0) and sample[u] >= 0.0:
        return
    p = wp.vec3(cell_corner(bcoord, u)) + wp.vec3(0.5)
    n = unit_normal(bmap, phi, p, out_v, in_v)
    if wp.length_sq(n) == 0.0:
        return
    a = wp.vec3(1.0, 0.0, 0.0)
    if wp.abs(n[0]) >= 0.9:
        a = wp.vec3(0.0, 1.0, 0.0)
    t1 = wp.normalize(wp.cross(n, a))
    t2 = wp.cross(n, t1)
    ndir = DIRECTIONS
    if sample[u] < 0.0:
        ndir = 2 * DIRECTIONS  # a corner: its faces are narrower wedges around it
    for k in range(ndir):
        ang = 2.0 * wp.pi * float(k) / float(ndir)
        d = t1 * wp.cos(ang) + t2 * wp.sin(ang)
        # the second point a step further along the surface from the first (not from the
        # cell: a point that far out along the cell's tangent plane can lie past the band)
        qa = onto_surface(bmap, phi, p + d * near, out_v, in_v)
        fa, ga = trilinear(bmap, phi, qa, out_v, in_v)
        if wp.abs(fa) >= 0.1:
            continue
        na = wp.normalize(ga)
        along = d - na * wp.dot(d, na)
        if wp.length_sq(along) < 0.25:
            continue
        along = wp.normalize(along)
        qb = onto_surface(bmap, phi, qa + along * (far - near), out_v, in_v)
        fb, gb = trilinear(bmap, phi, qb, out_v, in_v)
        if wp.abs(fb) >= 0.1:
            continue
        nb = wp.normalize(gb)
        if wp.dot(na, nb) <= cos_flat:
            continue
        if wp.abs(wp.dot(na, qb - qa)) >= plane_tol or wp.abs(wp.dot(nb, qa - qb)) >= plane_tol:
            continue
        sa = flat_beside(bmap, phi, qa, na, along, width, cos_flat, out_v, in_v)
        if wp.length_sq(sa) == 0.0:
            continue
        sb = flat_beside(bmap, phi, qb, nb, along, width, cos_flat, out_v, in_v)
        if wp.length_sq(sb) == 0.0:
            continue
        nk = wp.normalize(na + nb + sa + sb)  # six normals over 3 x 3 h: less of each one's noise
        ck = (qa + qb) * 0.5
        for m in range(CELL_PLANES):  # the first plane it matches, else the first free one
            i = s * CELL_PLANES + m
            if pw[i] == 0.0 or wp.dot(wp.normalize(pn[i]), nk) > cos_same:
                pn[i] = pn[i] + nk
                pp[i] = pp[i] + ck
                pw[i] = pw[i] + 1.0
                break
