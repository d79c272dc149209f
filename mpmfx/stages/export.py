"""Stage 4: USD for DCC tools (one crate layer per frame, stitched by value clips) and OpenVDB.

Output: `shot.usda` (root stage), `frames/NNNN.usdc` (per-frame layers) and
`vdb/<group>/NNNN.vdb` (level set `surface` + velocity `vel` per surface group, and the fog
volume `density` when surface.density is on).
"""

from __future__ import annotations

import numpy as np

from mpmfx.config import Shot
from mpmfx.geometry.colliders import collider_mesh, keyframes
from mpmfx.io.frames import GroupSurface, ParticleFrame, SurfaceFrame
from mpmfx.io.usd import ColliderSample, MeshSample, PointsSample, UsdShotWriter
from mpmfx.io.vdb import VdbGrid, write_vdb
from mpmfx.mpm.colliders import pose_matrix
from mpmfx.render.camera import default_camera
from mpmfx.stages.base import Context
from mpmfx.stages.colliders import animated_collider, collider_geometry
from mpmfx.stages.parallel import FrameJob
from mpmfx.surface.params import SparseLevelSet

NAME, VERSION, PER_FRAME, FRAME_EXT = "export", 1, True, "usdc"
CODE = (
    "mpmfx.stages.export",
    "mpmfx.io",
    "mpmfx.surface.params",
    "mpmfx.render.camera",
    "mpmfx.stages.colliders",
    "mpmfx.geometry.colliders",
    "mpmfx.geometry.animated",
    "mpmfx.geometry.mesh",
    "mpmfx.mpm.colliders",
)


def params(shot: Shot) -> dict:
    return {
        "export": shot.export.model_dump(mode="json"),
        "fps": shot.shot.fps,
        "frames": [shot.shot.frame_start, shot.shot.frame_end],
        "objects": [o.name for o in shot.bodies],
    }


def inputs(shot: Shot) -> dict[str, str]:
    return {}


def todo(ctx: Context) -> list[int]:
    return [f for f in ctx.frames if not ctx.entry.frame_path(f, FRAME_EXT).exists()]


def run(ctx: Context) -> dict:
    return finish(ctx, ctx.map_frames(frame, todo(ctx), desc="export"))


def frame(job: FrameJob, f: int) -> None:
    """Frame `f`'s .vdb files, then its USD layer (its existence marks the frame done): a task."""
    shot, entry = job.shot, job.entry
    surf, sim = job.upstream["surface"], job.upstream["simulate"]  # verified reads: a changed frame is redone
    groups = surf.read(surf.frame_path(f, SurfaceFrame.EXT), SurfaceFrame.read).groups
    volumes = _write_vdbs(shot, entry, f, groups) if shot.export.vdb else {}
    points = {}
    if shot.export.points:
        points = _points(shot, sim.read(sim.frame_path(f, ParticleFrame.EXT), ParticleFrame.read))
    _writer(shot, entry).write_frame(
        f, points=points, meshes=_meshes(groups), volumes=volumes, colliders=_colliders(shot, f)
    )


def finish(ctx: Context, results: list) -> dict:
    """In the client, after every frame's task: the root stage stitches the frames' layers."""
    root = _writer(ctx.shot, ctx.entry).finalize(ctx.entry.done_frames(FRAME_EXT), camera=_camera(ctx.shot))
    return {"usd": str(root)}


def _writer(shot: Shot, entry):
    return UsdShotWriter(
        entry.root / "shot.usda",
        fps=shot.shot.fps,
        start_frame=shot.shot.frame_start,
        end_frame=shot.shot.frame_end,
        up_axis="Y",
        meters_per_unit=1.0,
    )


def _points(shot: Shot, p: ParticleFrame) -> dict:
    out = {}
    for body, obj in enumerate(shot.bodies):
        sel = p.body == body
        primvars = {"material": p.material[sel], "body": p.body[sel]}
        if p.Jp is not None:
            primvars["Jp"] = p.Jp[sel]
        out[obj.name] = PointsSample(
            positions=p.x[sel],
            velocities=p.v[sel],
            widths=float(shot.particle_spacing),
            ids=p.id[sel].astype(np.int64),
            primvars=primvars,
        )
    return out


def _meshes(groups: dict) -> dict:
    return {
        g: MeshSample(points=d.vertices, face_vertex_indices=d.faces, normals=d.normals, velocities=d.velocities)
        for g, d in groups.items()
    }


def _colliders(shot: Shot, frame: int) -> list:
    """Each collider's mesh (local frame, m) and its pose at this frame, for USD."""
    t = (frame - shot.shot.frame_start) / shot.shot.fps
    out = []
    for i, col in enumerate(shot.colliders):
        if col.animated:  # world points at every frame, time-sampled
            _, pts, faces = animated_collider(shot, i)
            p, tri = pts[frame - shot.shot.frame_start].astype(np.float32), faces.astype(np.int32)
            out.append(ColliderSample(name=col.name, points=p, faces=tri, xform=np.eye(4), animated=True))
            continue
        geom = collider_geometry(col)
        m = collider_mesh(geom, resolve=shot.resolve, plane_size=2 * shot.domain.size)
        out.append(
            ColliderSample(
                name=col.name,
                points=np.asarray(m.vertices, np.float32),
                faces=np.asarray(m.faces, np.int32),
                xform=pose_matrix(*keyframes(geom), t),
            )
        )
    return out


def _write_vdbs(shot: Shot, entry, frame: int, groups: dict) -> dict:
    volumes = {}
    for g, d in groups.items():
        sparse = level_set(d)
        ls = sparse.to_dense()
        if ls.values.size == 0:
            continue
        ijk0 = tuple(int(i) for i in ls.ijk0)
        # half floats on disk: 27 % smaller files (jelly_splash), ~5e-4 relative, invisible in a render
        grids = [VdbGrid("surface", ls.values, ijk0, ls.voxel_size, "level_set", ls.background, half=True)]
        vel = sparse.velocity_dense(ls.ijk0, ls.values.shape)
        if vel is not None:
            grids.append(VdbGrid("vel", vel, ijk0, ls.voxel_size, "unknown", 0.0, half=True))
        density = sparse.density_dense(ls.ijk0, ls.values.shape)
        if density is not None:  # 0 outside the stored leaves: the writer leaves those voxels inactive
            grids.append(VdbGrid("density", density, ijk0, ls.voxel_size, "fog_volume", 0.0, half=True))
        rel = f"vdb/{g}/{frame:04d}.vdb"
        write_vdb(entry.root / rel, grids, metadata={"shot": shot.shot.name, "frame": frame, "units": "m", "group": g})
        volumes[g] = {grid.name: rel for grid in grids}
    return volumes


def level_set(d: GroupSurface) -> SparseLevelSet:
    """A stored group's leaves as `mpmfx.surface.SparseLevelSet` (to_dense / velocity_dense /
    density_dense)."""
    return SparseLevelSet(
        block_ijk=d.block_ijk,
        values=d.blocks,
        velocity=d.vel_blocks,
        inside_ijk=d.inside_ijk,
        voxel_size=float(d.voxel_size),
        background=float(d.background),
        density=d.density_blocks,
    )


def _camera(shot: Shot) -> dict:
    pos, look = default_camera(shot)
    return {"position": pos, "look_at": look, "focal_length": 35.0}
