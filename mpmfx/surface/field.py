"""Field pass: the raw field at the active voxels, from the gather (:mod:`mpmfx.surface.gather`),
its normal taken from the kernel weights blurred to SurfaceParams.normal_radius (the wide
normal), and the edges that bound the smoothing (:mod:`mpmfx.surface.edges`).
"""

from __future__ import annotations

import warp as wp

from mpmfx.surface import aniso_kernels as A
from mpmfx.surface.binning import sorted_velocity
from mpmfx.surface.edges import edges
from mpmfx.surface.grid import ANISO_MAX_STRETCH, NORMAL_STEP, SparseGrid
from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import launch_blocks, launch_sequence, split
from mpmfx.surface.lines import block_faces, line_neighbours, line_sides, row_steps, rows, side_code, vec8
from mpmfx.surface.params import SurfaceParams
from mpmfx.surface.voxels import BS, BV, TILE_INSIDE, block_tile, line_start, voxel_of, weight_at

BLUR_MIN_SPLIT = (
    1024  # blocks below which the weight blur's passes run on one CPU thread (a pass's barrier costs ~20-50 us)
)
ANISO_NORMAL_ITERS = 4  # inverse-power iterations that turn the normal towards the neighbours' thinnest axis
ANISO_COV_EPS = 0.01  # x kernel radius^2: regularises the covariance of a flat (lattice) sheet
ANISO_MAX_RATIO = 4.0  # Yu & Turk's k_r: an ellipsoid's axes differ by at most this factor
ANISO_MIN_NEIGHBOURS = 8  # fewer neighbours within the kernel (spray) keep a round kernel; a one-layer sheet has ~15

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


@wp.kernel
def blur_weight_axis(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=float),
    axis: int,
    step: int,
    dst: wp.array(dtype=float),
    base: int,
):
    """dst = [1 2 1]/4 blur of the kernel weight sum along `axis` with taps `step` (< BS) voxels
    apart (variance 0.5 step^2 voxel^2; tiles as in weight_at), on the 8 voxels of one line
    along `axis` (thread = line, 64 a block): the blocks before and after the line are looked
    up once, not by every voxel within `step` of the block's faces."""
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
    ripple the weight blur's 2-voxel taps keep: a blur without it would leave n in the sheet's
    plane.)"""
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
            bmap, wide, t, c[0] - o[0], c[1] - o[1], c[2] - o[2]
        )
    if aniso != 0:
        ci = wp.inverse(cov[t] + cov_eps * wp.identity(n=3, dtype=float))
        for it in range(cov_iters):  # noqa: B007 - a fixed-count loop
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
def weight_row(src: wp.array(dtype=vec8), code: int, r: int, own: vec8):
    """weight_at for a row: row r of the block with code `code`, 0 on an OUTSIDE tile, the
    voxels' own values `own` on an INSIDE one."""
    if code >= 0:
        return src[code * 64 + r]
    if code == TILE_INSIDE:
        return own
    return vec8(0.0)


@cpu_kernel
def blur_weight_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    src: wp.array(dtype=vec8),
    axis: int,
    dst: wp.array(dtype=vec8),
    base: int,
):
    """blur_weight_axis with step 2 on one block (thread = block), 8 voxels at a
    time (src, dst: the weights as vec8 rows along z; along x or y a row's neighbours are whole
    rows, along z a row is a line and its neighbours the row shifted): each voxel gets 0.25
    (2 before) + 0.5 itself + 0.25 (2 after), in that order, a tap on an OUTSIDE tile 0, on an
    INSIDE one the voxel's own value (weight_at)."""
    b = wp.tid() + base
    below = side_code(bmap, bcoord[b], axis, -1)
    above = side_code(bmap, bcoord[b], axis, 1)
    r0 = b * 64
    if axis == 2:
        for l in range(64):
            c = src[r0 + l]
            lo = weight_row(src, below, l, c)
            hi = weight_row(src, above, l, c)
            if below == TILE_INSIDE:  # the taps before voxels 0 and 1 read those voxels
                lo = vec8(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, c[0], c[1])
            if above == TILE_INSIDE:
                hi = vec8(c[6], c[7], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            m2 = vec8(lo[6], lo[7], c[0], c[1], c[2], c[3], c[4], c[5])
            p2 = vec8(c[2], c[3], c[4], c[5], c[6], c[7], hi[0], hi[1])
            dst[r0 + l] = 0.25 * m2 + 0.5 * c + 0.25 * p2
        return
    sa, so = row_steps(axis)
    for o in range(BS):
        c0 = src[r0 + o * so]
        c1 = src[r0 + sa + o * so]
        c2 = src[r0 + 2 * sa + o * so]
        c3 = src[r0 + 3 * sa + o * so]
        c4 = src[r0 + 4 * sa + o * so]
        c5 = src[r0 + 5 * sa + o * so]
        c6 = src[r0 + 6 * sa + o * so]
        c7 = src[r0 + 7 * sa + o * so]
        l6 = weight_row(src, below, 6 * sa + o * so, c0)
        l7 = weight_row(src, below, 7 * sa + o * so, c1)
        h0 = weight_row(src, above, o * so, c6)
        h1 = weight_row(src, above, sa + o * so, c7)
        dst[r0 + o * so] = 0.25 * l6 + 0.5 * c0 + 0.25 * c2
        dst[r0 + sa + o * so] = 0.25 * l7 + 0.5 * c1 + 0.25 * c3
        dst[r0 + 2 * sa + o * so] = 0.25 * c0 + 0.5 * c2 + 0.25 * c4
        dst[r0 + 3 * sa + o * so] = 0.25 * c1 + 0.5 * c3 + 0.25 * c5
        dst[r0 + 4 * sa + o * so] = 0.25 * c2 + 0.5 * c4 + 0.25 * c6
        dst[r0 + 5 * sa + o * so] = 0.25 * c3 + 0.5 * c5 + 0.25 * c7
        dst[r0 + 6 * sa + o * so] = 0.25 * c4 + 0.5 * c6 + 0.25 * h0
        dst[r0 + 7 * sa + o * so] = 0.25 * c5 + 0.5 * c7 + 0.25 * h1


@cpu_kernel
def project_on_wide_normal_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    wide: wp.array(dtype=float),
    w: wp.array(dtype=float),
    offset: wp.array(dtype=wp.vec3),
    radius_vox: float,
    far_vox: float,
    phi: wp.array(dtype=float),
    base: int,
):
    """project_on_wide_normal (isotropic kernels) on one block (thread = block),
    the neighbour blocks looked up once (weight_at: 0 on an OUTSIDE tile, the voxel's own value
    on an INSIDE one)."""
    b = wp.tid() + base
    faces = block_faces(bmap, bcoord[b])
    for l in range(64):
        sides = line_sides(faces, l // BS, l - (l // BS) * BS)
        for z in range(BS):
            t = (b * 64 + l) * BS + z
            if w[t] <= 0.0:
                phi[t] = far_vox
                continue
            n = line_neighbours(wide, sides, t, l, z, 0.0, wide[t])
            g = wp.vec3(n[1] - n[0], n[3] - n[2], n[5] - n[4])
            d = offset[t]
            dist = wp.length(d)
            gl = wp.length(g)
            if gl > 0.0:
                dist = -wp.dot(d, g) / gl  # g points inward (towards the particles)
            phi[t] = dist - radius_vox


def field(variant, bcoord, bmap, cells, starts, order, gs, v, grid: SparseGrid, params: SurfaceParams):
    """The raw Zhu-Bridson field at the active voxels: (phi (voxels), kernel weight sums w,
    kernel-weighted velocity or a 1-element placeholder, the edges for the smoothing's limit
    (mpmfx.surface.edges; None without smoothing)), isotropic or with Yu & Turk's ellipsoids
    (params.anisotropic). variant: the device's passes (mpmfx.surface.variants); gs: the
    particles' grid positions in the cells' order, v: their velocities in the caller's order
    (or None)."""
    nvox = bcoord.shape[0] * BS**3
    with_v = v is not None
    phi, w = wp.empty(nvox, dtype=float), wp.empty(nvox, dtype=float)
    vel = wp.empty(nvox if with_v else 1, dtype=wp.vec3)
    if nvox == 0:
        return phi, w, vel, None
    offset = wp.empty(nvox, dtype=wp.vec3)
    aniso = params.anisotropic
    cov = wp.empty(nvox if aniso else 1, dtype=wp.mat33)
    radius = wp.empty(nvox if aniso else 1, dtype=float)
    n = gs.shape[0]
    vs = wp.empty(n if with_v else 1, dtype=wp.vec3)  # v in the cells' order, as gs; non-finite ones 0
    if with_v:
        split(wp, sorted_velocity, n, [v, order, vs])
    if aniso:
        gmat, thin = wp.empty(n, dtype=wp.mat33), wp.empty(n, dtype=float)
        wp.launch(
            A.particle_shape,
            n,
            inputs=[
                gs,
                cells,
                starts,
                grid.kernel_vox,
                ANISO_MAX_RATIO,
                ANISO_MAX_STRETCH,
                ANISO_MIN_NEIGHBOURS,
                gmat,
                thin,
            ],
        )
        wp.launch(
            A.gather_zhu_bridson_aniso,
            nvox,
            inputs=[
                bcoord,
                cells,
                starts,
                gs,
                gmat,
                thin,
                vs,
                int(with_v),
                grid.gather_vox,
                grid.kernel_vox,
                grid.r_vox,
                grid.far_vox,
            ],
            outputs=[phi, w, offset, vel, cov, radius],
        )
    else:
        variant.gather(bcoord, cells, starts, gs, vs, int(with_v), grid, phi, w, offset, vel)
    wide = w
    if grid.normal_passes > 0:
        wide = variant.blur_weights(bcoord, bmap, w, grid.normal_passes)
        project = project_by_voxel if aniso else variant.project_normal
        project(bcoord, bmap, wide, w, offset, grid, aniso, cov, radius, phi)
    found = edges(bcoord, bmap, wide, offset, phi, grid) if params.smooth_iters > 0 else None
    return phi, w, vel, found


def project_by_voxel(bcoord, bmap, wide, w, offset, grid: SparseGrid, aniso: bool, cov, radius, phi) -> None:
    """phi from the kernel centroid's offset projected on the wide normal (the blurred weights'
    gradient), a voxel per thread."""
    split(
        wp,
        project_on_wide_normal,
        phi.shape[0],
        [
            bcoord,
            bmap,
            wide,
            w,
            offset,
            grid.r_vox,
            grid.far_vox,
            int(aniso),
            cov,
            ANISO_NORMAL_ITERS,
            ANISO_COV_EPS * grid.kernel_vox**2,
            radius,
            phi,
        ],
    )


def project_by_block(bcoord, bmap, wide, w, offset, grid: SparseGrid, aniso: bool, cov, radius, phi) -> None:
    """project_by_voxel for the isotropic field, a block per thread."""
    launch_blocks(wp, project_on_wide_normal_lines, [bcoord, bmap, wide, w, offset, grid.r_vox, grid.far_vox, phi])


def blur_by_voxel(bcoord, bmap, w, passes: int):
    """The kernel weight sums blurred `passes` times along each axis (a new array), a line per thread."""
    return _blur(
        bcoord, bmap, w, passes, lambda a, axis, b: (blur_weight_axis, [bcoord, bmap, a, axis, NORMAL_STEP, b]), BS * BS
    )


def blur_by_block(bcoord, bmap, w, passes: int):
    """blur_by_voxel, a block per thread (written out for NORMAL_STEP 2)."""
    if NORMAL_STEP != 2:
        return blur_by_voxel(bcoord, bmap, w, passes)
    return _blur(
        bcoord, bmap, w, passes, lambda a, axis, b: (blur_weight_lines, [bcoord, bmap, rows(a), axis, rows(b)]), 1
    )


def _blur(bcoord, bmap, w, passes: int, step, per_block: int):
    # the first pass reads w itself (no copy of it), then two buffers take turns
    a, b = w, wp.empty_like(w)
    steps = []
    for _ in range(passes):
        for axis in range(3):
            steps.append(step(a, axis, b))
            a, b = b, (wp.empty_like(w) if a is w else a)
    # many light passes at the shots' setting (0.4-0.5 ms each at 100k "fine"): split, each
    # would pay a hand-off to the pool; as a sequence, one
    launch_sequence(wp, steps, bcoord.shape[0] * per_block, device=w.device, min_split=BLUR_MIN_SPLIT)
    return a
