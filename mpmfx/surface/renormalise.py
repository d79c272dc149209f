"""The level set renormalised: phi / |grad phi| (central differences), scaled and clipped, a
voxel per thread (GPU) or a block per thread (CPU)."""

from __future__ import annotations

import warp as wp

from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import launch_blocks, split
from mpmfx.surface.lines import block_faces, line_sides, neighbour_rows, rows, vec8
from mpmfx.surface.voxels import BS, step_get, voxel_of

NO_FAR = 3.0e38  # renormalise's `far` where every value is renormalised

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


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
    out[t] = wp.where(
        wp.abs(v) >= far, wp.where(v > 0.0, clip, -clip), wp.clamp(v / wp.max(grad, 0.05) * scale, -clip, clip)
    )


@cpu_kernel
def renormalise_lines(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=vec8),
    out_v: float,
    in_v: float,
    scale: float,
    clip: float,
    far: float,
    out: wp.array(dtype=vec8),
    base: int,
):
    """renormalise on the 64 lines along z of one block (thread = block), phi and
    out as vec8 rows (rows): a line's neighbour lines are one load each, the differences vec8
    operations, the gradient's length and the division per voxel as renormalise has them."""
    b = wp.tid() + base
    faces = block_faces(bmap, bcoord[b])
    for l in range(64):
        r = b * 64 + l
        sides = line_sides(faces, l // BS, l - (l // BS) * BS)
        xm, xp, ym, yp, lo, hi = neighbour_rows(phi, sides, r, l, out_v, in_v)
        dx = xp - xm
        dy = yp - ym
        dz = hi - lo
        own = phi[r]
        res = vec8(0.0)
        for z in range(BS):
            grad = 0.5 * wp.length(wp.vec3(dx[z], dy[z], dz[z]))
            v = own[z]
            res[z] = wp.where(
                wp.abs(v) >= far, wp.where(v > 0.0, clip, -clip), wp.clamp(v / wp.max(grad, 0.05) * scale, -clip, clip)
            )
        out[r] = res


def renormalise_by_voxel(bcoord, bmap, phi, tiles, scale: float, clip: float, out, *, far: float = NO_FAR) -> None:
    """out = renormalise of phi, a voxel per thread; |phi| of `far` or more gives +-clip."""
    split(wp, renormalise, phi.shape[0], [bcoord, bmap, phi, *tiles, scale, clip, far, out])


def renormalise_by_block(bcoord, bmap, phi, tiles, scale: float, clip: float, out, *, far: float = NO_FAR) -> None:
    """renormalise_by_voxel, a block line per thread."""
    launch_blocks(wp, renormalise_lines, [bcoord, bmap, rows(phi), *tiles, scale, clip, far, rows(out)])
