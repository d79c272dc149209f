"""Stage 3: each frame's particles become narrow-band level sets and meshes (world units).

Output `frames/NNNN.npz`: for each surface group G (a material, an object, or "all"):
`G.vertices` (m,3) float32 m, `G.faces` (k,3) int32, `G.normals`, `G.velocities` (m,3) m/s, and
the sparse level set as 8^3 leaves (its size follows the surface area, not the domain):
`G.block_ijk` (b,3) int64, `G.blocks` (b,8,8,8) float32 m, `G.vel_blocks` (b,8,8,8,3) m/s,
`G.inside_ijk` (k,3) int64 (leaves wholly inside), `G.voxel_size`, `G.background`, and with
`surface.density` on `G.density_blocks` (b,8,8,8) float16 fog density 0..1 (1 on the inside leaves).
`groups` lists the group names.
"""
from __future__ import annotations

import numpy as np

from mpmfx.cache import code_hash

from mpmfx.config import Shot, SurfaceGroup
from mpmfx.io.frames import read_arrays, write_arrays
from mpmfx.stages.base import Context, quiet_warp

NAME, VERSION, PER_FRAME, FRAME_EXT = "surface", 2, True, "npz"


def params(shot: Shot) -> dict:
    # The resolved surfacer parameters, not the config section: a changed default re-runs surface.
    resolved = {k: getattr(v, "value", v) for k, v in vars(surface_params(shot)).items()}
    return {"surface": resolved, "groups": group_names(shot)}


def inputs(shot: Shot) -> dict[str, str]:
    return {"code": code_hash("mpmfx.surface", __file__)}


def particle_spacing(shot: Shot) -> float:
    """Mean particle spacing (m): dx / ppc^(1/3)."""
    return shot.domain.size / shot.domain.grid_n / shot.voxelise.ppc ** (1 / 3)


def group_names(shot: Shot) -> list[str]:
    """Surface group per object: its material preset name, its own name, or 'all'."""
    g = shot.surface.group
    if g is SurfaceGroup.OBJECT:
        return [o.name for o in shot.objects]
    if g is SurfaceGroup.MATERIAL:
        return [o.material for o in shot.objects]
    return ["all" for _ in shot.objects]


def surface_params(shot: Shot):
    from mpmfx.surface import SurfaceParams
    s = shot.surface
    h = particle_spacing(shot)
    # Default voxel: half the particle spacing, fine enough for a smooth render and ~10x cheaper
    # than the surfacer's own default (a quarter of the radius).
    return SurfaceParams(particle_radius=0.6 * h, radius_scale=s.radius_scale,
                         voxel_size=s.voxel_size or 0.5 * h, dense_output=False, smooth_iters=s.smooth_iters, dilate=s.dilate,
                         min_feature_particles=s.min_feature_particles, density=s.density)


def run(ctx: Context) -> dict:
    from mpmfx.stages.simulate import load_frame
    from mpmfx.surface import surface_particles

    quiet_warp(ctx.device)
    shot, entry = ctx.shot, ctx.entry
    sp = surface_params(shot)
    names = group_names(shot)
    groups = sorted(set(names))
    todo = [f for f in ctx.frames if not entry.frame_path(f, FRAME_EXT).exists()]
    stats = {"vertices": 0, "faces": 0}
    for f in ctx.progress(todo, total=len(todo), desc="surface"):
        p = load_frame(ctx.upstream["simulate"], f)
        group_of = np.asarray([groups.index(n) for n in names], np.int32)[p["body"]]
        out: dict[str, np.ndarray] = {"groups": np.asarray(groups)}
        for gi, g in enumerate(groups):
            sel = group_of == gi
            res = surface_particles(p["x"][sel], p["v"][sel], sp, device=ctx.device)
            m, ls = res.mesh, res.sparse
            out |= {f"{g}.vertices": m.vertices, f"{g}.faces": m.faces, f"{g}.normals": m.normals,
                    f"{g}.velocities": m.velocities, f"{g}.block_ijk": ls.block_ijk, f"{g}.blocks": ls.values,
                    f"{g}.inside_ijk": ls.inside_ijk, f"{g}.voxel_size": np.float64(ls.voxel_size),
                    f"{g}.background": np.float64(ls.background)}
            if ls.velocity is not None:  # motion-blur vectors: half precision is plenty, and half the bytes
                out[f"{g}.vel_blocks"] = ls.velocity.astype(np.float16)
            if ls.density is not None:  # 0..1 for a fog shader: float16's 5e-4 steps are invisible
                out[f"{g}.density_blocks"] = ls.density.astype(np.float16)
            stats["vertices"] += len(m.vertices)
            stats["faces"] += len(m.faces)
        # the level set is mostly +-background, the fog mostly exact 0 and 1: both deflate ~2.5x
        squeeze = [f"{g}.{k}" for g in groups for k in ("blocks", "density_blocks")]
        write_arrays(entry.frame_path(f, FRAME_EXT), out, compress=squeeze)
    return {"this_run": stats}


def level_set(group: dict):
    """A group's stored leaves as `mpmfx.surface.SparseLevelSet` (to_dense / velocity_dense /
    density_dense)."""
    from mpmfx.surface import SparseLevelSet
    return SparseLevelSet(block_ijk=group["block_ijk"], values=group["blocks"], velocity=group.get("vel_blocks"),
                          inside_ijk=group["inside_ijk"], voxel_size=float(group["voxel_size"]),
                          background=float(group["background"]), density=group.get("density_blocks"))


def load_frame_groups(entry, frame: int) -> dict[str, dict[str, np.ndarray]]:
    """{group: {vertices, faces, normals, velocities, block_ijk, blocks, inside_ijk, voxel_size,
    background[, vel_blocks][, density_blocks]}} (see the module docstring)."""
    data = read_arrays(entry.frame_path(frame, FRAME_EXT))
    return {str(g): {k.split(".", 1)[1]: v for k, v in data.items() if k.startswith(f"{g}.")}
            for g in data["groups"]}
