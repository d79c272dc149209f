"""Stage 3: each frame's particles become narrow-band level sets and meshes (world units).

Output `frames/NNNN.npz`: an `mpmfx.io.frames.SurfaceFrame` record, one `GroupSurface` per
surface group (a material, an object, or "all": `surface.group`): the mesh with vertex normals
and velocities, and the sparse level set as 8^3 leaves (its size follows the surface area, not
the domain), with velocity leaves and, with `surface.density` on, fog density leaves.
"""
from __future__ import annotations

import numpy as np

from mpmfx.config import Shot
from mpmfx.io.frames import GroupSurface, ParticleFrame, SurfaceFrame
from mpmfx.stages.base import Context, quiet_warp

NAME, VERSION, PER_FRAME, FRAME_EXT = "surface", 2, True, SurfaceFrame.EXT
CODE = ("mpmfx.stages.surface", "mpmfx.surface", "mpmfx.io.frames")


def params(shot: Shot) -> dict:
    # The resolved surfacer parameters, not the config section: a changed default re-runs surface.
    resolved = {k: getattr(v, "value", v) for k, v in vars(surface_params(shot)).items()}
    return {"surface": resolved, "groups": shot.surface_groups()}


def inputs(shot: Shot) -> dict[str, str]:
    return {}


def surface_params(shot: Shot):
    from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams
    s = shot.surface
    h = shot.particle_spacing
    # Default voxel: half the particle spacing, fine enough for a smooth render and ~10x cheaper
    # than the surfacer's own default (a quarter of the radius).
    return SurfaceParams(particle_radius=PARTICLE_RADIUS_PER_SPACING * h, radius_scale=s.radius_scale,
                         voxel_size=s.voxel_size or 0.5 * h, dense_output=False, smooth_iters=s.smooth_iters, dilate=s.dilate,
                         min_feature_particles=s.min_feature_particles, density=s.density)


def run(ctx: Context) -> dict:
    from mpmfx.surface import surface_particles

    quiet_warp(ctx.device)
    shot, entry = ctx.shot, ctx.entry
    sp = surface_params(shot)
    names = shot.surface_groups()
    groups = sorted(set(names))
    todo = [f for f in ctx.frames if not entry.frame_path(f, FRAME_EXT).exists()]
    stats = {"vertices": 0, "faces": 0}
    for f in ctx.progress(todo, total=len(todo), desc="surface"):
        p = ParticleFrame.read(ctx.upstream["simulate"].frame_path(f, ParticleFrame.EXT))
        group_of = np.asarray([groups.index(n) for n in names], np.int32)[p.body]
        out = {}
        for gi, g in enumerate(groups):
            sel = group_of == gi
            res = surface_particles(p.x[sel], p.v[sel], sp, device=ctx.device)
            m, ls = res.mesh, res.sparse
            out[g] = GroupSurface(
                vertices=m.vertices, faces=m.faces, normals=m.normals, velocities=m.velocities,
                block_ijk=ls.block_ijk, blocks=ls.values, inside_ijk=ls.inside_ijk, voxel_size=ls.voxel_size,
                background=ls.background,
                # motion-blur vectors: half precision is plenty, and half the bytes
                vel_blocks=None if ls.velocity is None else ls.velocity.astype(np.float16),
                # 0..1 for a fog shader: float16's 5e-4 steps are invisible
                density_blocks=None if ls.density is None else ls.density.astype(np.float16))
            stats["vertices"] += len(m.vertices)
            stats["faces"] += len(m.faces)
        SurfaceFrame(out).write(entry.frame_path(f, FRAME_EXT))
    return {"this_run": stats}
