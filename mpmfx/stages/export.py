"""Stage 4: USD for DCC tools (one crate layer per frame, stitched by value clips) and OpenVDB.

Output: `shot.usda` (root stage), `frames/NNNN.usdc` (per-frame layers) and
`vdb/<group>/NNNN.vdb` (level set `surface` + velocity `vel` per surface group, and the fog
volume `density` when surface.density is on).
"""
from __future__ import annotations

import numpy as np

from mpmfx.cache import code_hash
from mpmfx.config import Shot
from mpmfx.stages.base import Context

NAME, VERSION, PER_FRAME, FRAME_EXT = "export", 1, True, "usdc"


def params(shot: Shot) -> dict:
    return {"export": shot.export.model_dump(mode="json"), "fps": shot.shot.fps,
            "frames": [shot.shot.frame_start, shot.shot.frame_end],
            "objects": [o.name for o in shot.objects]}


def inputs(shot: Shot) -> dict[str, str]:
    return {"code": code_hash("mpmfx.io", __file__)}


def run(ctx: Context) -> dict:
    from mpmfx.stages import colliders, simulate
    from mpmfx.stages.surface import load_frame_groups, particle_spacing

    shot, entry = ctx.shot, ctx.entry
    writer = _writer(shot, entry)
    spacing = particle_spacing(shot)
    todo = [f for f in ctx.frames if not entry.frame_path(f, FRAME_EXT).exists()]
    for f in ctx.progress(todo, total=len(todo), desc="export"):
        groups = load_frame_groups(ctx.upstream["surface"], f)
        volumes = _write_vdbs(shot, entry, f, groups) if shot.export.vdb else {}
        points = _points(shot, simulate.load_frame(ctx.upstream["simulate"], f), spacing) if shot.export.points else {}
        writer.write_frame(f, points=points, meshes=_meshes(groups), volumes=volumes,
                           colliders=colliders.usd_samples(shot, f))
    done = entry.done_frames(FRAME_EXT)
    root = writer.finalize(done, camera=_camera(shot))
    return {"usd": str(root)}


def _writer(shot: Shot, entry):
    from mpmfx.io.usd import UsdShotWriter
    return UsdShotWriter(entry.root / "shot.usda", fps=shot.shot.fps, start_frame=shot.shot.frame_start,
                         end_frame=shot.shot.frame_end, up_axis="Y", meters_per_unit=1.0)


def _points(shot: Shot, p: dict, spacing: float) -> dict:
    from mpmfx.io.usd import PointsSample
    out = {}
    for body, obj in enumerate(shot.objects):
        sel = p["body"] == body
        primvars = {"material": p["material"][sel], "body": p["body"][sel]}
        if "Jp" in p:
            primvars["Jp"] = p["Jp"][sel]
        out[obj.name] = PointsSample(
            positions=p["x"][sel], velocities=p["v"][sel], widths=float(spacing),
            ids=p["id"][sel].astype(np.int64), primvars=primvars)
    return out


def _meshes(groups: dict) -> dict:
    from mpmfx.io.usd import MeshSample
    return {g: MeshSample(points=d["vertices"], face_vertex_indices=d["faces"], normals=d["normals"],
                                       velocities=d["velocities"]) for g, d in groups.items()}


def _write_vdbs(shot: Shot, entry, frame: int, groups: dict) -> dict:
    from mpmfx.io.vdb import VdbGrid, write_vdb
    from mpmfx.stages.surface import level_set
    volumes = {}
    for g, d in groups.items():
        sparse = level_set(d)
        ls = sparse.to_dense()
        if ls.values.size == 0:
            continue
        ijk0 = tuple(int(i) for i in ls.ijk0)
        grids = [VdbGrid("surface", ls.values, ijk0, ls.voxel_size, "level_set", ls.background)]
        vel = sparse.velocity_dense(ls.ijk0, ls.values.shape)
        if vel is not None:
            grids.append(VdbGrid("vel", vel, ijk0, ls.voxel_size, "unknown", 0.0))
        density = sparse.density_dense(ls.ijk0, ls.values.shape)
        if density is not None:  # 0 outside the stored leaves: the writer leaves those voxels inactive
            grids.append(VdbGrid("density", density, ijk0, ls.voxel_size, "fog_volume", 0.0))
        rel = f"vdb/{g}/{frame:04d}.vdb"
        write_vdb(entry.root / rel, grids, metadata={"shot": shot.shot.name, "frame": frame, "units": "m",
                                                     "group": g})
        volumes[g] = {grid.name: rel for grid in grids}
    return volumes


def _camera(shot: Shot) -> dict:
    from mpmfx.render.camera import default_camera
    pos, look = default_camera(shot)
    return {"position": pos, "look_at": look, "focal_length": 35.0}
