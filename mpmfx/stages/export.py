"""Stage 4: USD for DCC tools (one crate layer per frame, stitched by value clips) and OpenVDB.

Output: `shot.usda` (root stage), `frames/NNNN.usdc` (per-frame layers) and
`vdb/<group>/NNNN.vdb` (level set `surface` + velocity `vel` per surface group, and the fog
volume `density` when surface.density is on).

The stage is the hand-off to a DCC: surfaces named after the shot's objects
(`mpmfx.stages.names`), each with the material of its render look; particles and level sets
hidden; the camera the render looks through; the time codes of the frames run.
"""

from __future__ import annotations

import time
from functools import partial

import numpy as np

from mpmfx.config import Shot
from mpmfx.geometry.colliders import collider_mesh, keyframes
from mpmfx.io.frames import GroupSurface, ParticleFrame, SurfaceFrame
from mpmfx.io.usd import ColliderSample, MeshSample, PointsSample, UsdShotWriter
from mpmfx.io.usd_view import PreviewLook
from mpmfx.mpm.colliders import pose_matrix
from mpmfx.render.camera import camera_inputs, frames_bounds, render_camera
from mpmfx.render.looks import preview_surface
from mpmfx.stages import grids
from mpmfx.stages.base import Context
from mpmfx.stages.colliders import animated_collider, collider_geometry
from mpmfx.stages.names import surface_looks, usd_names
from mpmfx.stages.parallel import FrameJob
from mpmfx.surface.params import SparseLevelSet

NAME, VERSION, PER_FRAME, FRAME_EXT = "export", 2, True, "usdc"
MESH = ("vertices", "faces", "normals", "velocities")  # what a surface frame gives the USD layer
CAMERA_SAMPLES = 12  # frames whose bounds the render camera frames (evenly spaced over those run)
CODE = (
    "mpmfx.stages.export",
    "mpmfx.stages.grids",
    "mpmfx.stages.names",
    "mpmfx.io",
    "mpmfx.surface.params",
    "mpmfx.render.camera",
    "mpmfx.render.looks",
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
        "names": usd_names(shot).__dict__,
        "looks": surface_looks(shot),
        "camera": camera_inputs(shot),  # what the render camera depends on (`render_camera`)
    }


def inputs(shot: Shot) -> dict[str, str]:
    return {}


def todo(ctx: Context) -> list[int]:
    return [f for f in ctx.frames if not ctx.entry.frame_path(f, FRAME_EXT).exists()]


def run(ctx: Context) -> dict:
    return finish(ctx, ctx.map_frames(frame, todo(ctx), desc="export"))


def frame(job: FrameJob, f: int) -> dict[str, float]:
    """Frame `f`'s .vdb files, then its USD layer (its existence marks the frame done): a task.
    Returns where its time went, s: read (the upstream frames), vdb (waiting for the grids, which
    child processes build and write from the leaves meanwhile: `mpmfx.stages.grids`), usd (the
    layer built in memory), write (the layer written and read back)."""
    shot, entry = job.shot, job.entry
    surf, sim = job.upstream["surface"], job.upstream["simulate"]  # verified reads: a changed frame is redone
    t0 = time.perf_counter()
    # the mesh only: the leaves, most of the file, are read by the grids' own processes
    groups = surf.read(surf.frame_path(f, SurfaceFrame.EXT), partial(SurfaceFrame.read, fields=MESH)).groups
    pending = grids.submit(job, f, list(groups)) if shot.export.vdb else {}
    particles = sim.read(sim.frame_path(f, ParticleFrame.EXT), ParticleFrame.read) if shot.export.points else None
    t1 = time.perf_counter()
    points = _points(shot, particles) if particles is not None else {}
    names = usd_names(shot)
    meshes = {names.surfaces[g]: m for g, m in _meshes(groups).items()}
    colliders = _colliders(shot, f)
    t2 = time.perf_counter()
    volumes = grids.results(pending)
    split = {"read": t1 - t0, "vdb": time.perf_counter() - t2}
    seconds = {"usd": t2 - t1}
    _writer(shot, entry).write_frame(
        f,
        points=points,
        meshes=meshes,
        volumes={names.volumes[g]: v for g, v in volumes.items() if v},
        colliders=colliders,
        seconds=seconds,
    )
    return {**split, **seconds}


def finish(ctx: Context, results: list) -> dict:
    """In the client, after every frame's task: the root stage stitches the frames' layers, with
    the render camera (framing what the frames show) and each surface's material. The camera
    goes in the manifest too: the render stage looks through it, and `seconds_split`, the
    frames' time summed (`frame`)."""
    frames = ctx.entry.done_frames(FRAME_EXT)
    camera = render_camera(ctx.shot, _bounds(ctx, frames))
    names = usd_names(ctx.shot)
    looks = {
        names.surfaces[g]: PreviewLook(look, **preview_surface(look)) for g, look in surface_looks(ctx.shot).items()
    }
    root = _writer(ctx.shot, ctx.entry).finalize(frames, camera=camera, looks=looks)
    split: dict[str, float] = {}
    for seconds in results:  # the frames this run made (`frame`'s split; None from older tasks)
        for k, s in (seconds or {}).items():
            split[k] = split.get(k, 0.0) + s
    return {"usd": str(root), "camera": camera, "seconds_split": {k: round(s, 3) for k, s in split.items()}}


def _bounds(ctx: Context, frames: list[int]):
    """(lo, hi) m of what the render shows (surfaces, or particles in render.mode particles, and
    the colliders) over up to CAMERA_SAMPLES of `frames`; None when nothing is there."""
    shot = ctx.shot
    if not frames_bounds(shot):
        return None  # the camera is the config's or the 3/4 view: no frame is read
    n = len(frames)
    picks = sorted({frames[round(i * (n - 1) / (CAMERA_SAMPLES - 1))] for i in range(CAMERA_SAMPLES)}) if n else []
    pts = []
    for f in picks:
        if shot.render.mode == "particles":
            sim = ctx.upstream["simulate"]
            pts.append(sim.read(sim.frame_path(f, ParticleFrame.EXT), ParticleFrame.read).x)
        else:
            up = ctx.upstream["surface"]
            groups = up.read(up.frame_path(f, SurfaceFrame.EXT), SurfaceFrame.read).groups
            pts += [d.vertices for d in groups.values()]
        pts += [c.points @ c.xform[:3, :3].T + c.xform[:3, 3] for c in _colliders(shot, f)]
    pts = [np.asarray(p, np.float64).reshape(-1, 3) for p in pts if len(p)]
    if not pts:
        return None
    allp = np.concatenate(pts)
    return allp.min(axis=0), allp.max(axis=0)


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
    out, names = {}, usd_names(shot).particles
    for body, obj in enumerate(shot.bodies):
        sel = p.body == body
        primvars = {"material": p.material[sel], "body": p.body[sel]}
        if p.Jp is not None:
            primvars["Jp"] = p.Jp[sel]
        out[names[obj.name]] = PointsSample(
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
