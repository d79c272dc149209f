"""Stage 5: PNG frames and an mp4 of the surfaces (or the particle debug look).

Output in the cache entry: `frames/NNNN.png` and `<shot>.mp4`; both are then published to
`renders/<shot>/`, the folder artists look in.
"""
from __future__ import annotations

import shutil
from pathlib import Path

from mpmfx.cache import atomic_path
from mpmfx.config import Shot
from mpmfx.io.frames import ParticleFrame, SurfaceFrame
from mpmfx.stages.base import Context
from mpmfx.stages.parallel import FrameJob

NAME, VERSION, PER_FRAME, FRAME_EXT = "render", 1, True, "png"
CODE = ("mpmfx.stages.render", "mpmfx.render", "mpmfx.io.frames", "mpmfx.geometry.colliders",
        "mpmfx.geometry.mesh", "mpmfx.mpm.colliders")


def params(shot: Shot) -> dict:
    from mpmfx.render.camera import default_camera
    return {"render": shot.render.model_dump(mode="json"), "camera": default_camera(shot),
            "domain": shot.domain.model_dump(mode="json"), "materials": [o.material for o in shot.objects],
            "colliders": [c.model_dump(mode="json") for c in shot.colliders]}


def inputs(shot: Shot) -> dict[str, str]:
    return {}


def todo(ctx: Context) -> list[int]:
    return [f for f in ctx.frames if not ctx.entry.frame_path(f, FRAME_EXT).exists()]


def run(ctx: Context) -> dict:
    try:
        return finish(ctx, ctx.map_frames(frame, todo(ctx), desc="render"))
    finally:
        close()  # the serial path's renderer; a worker's ends with the worker


def frame(job: FrameJob, f: int) -> None:
    """Render frame `f` into the entry (a task: runs on any worker)."""
    from mpmfx.render.frames import colour_for

    shot = job.shot
    r = shot.render
    renderer = _renderer(job)
    label = f"frame {f}  t={(f - shot.shot.frame_start) / shot.shot.fps:.2f}s"
    # The renderer writes through its own temp name; this one is unique per writer, so two
    # workers rendering one frame never share a temp file, and the frame is complete or absent.
    with atomic_path(job.entry.frame_path(f, FRAME_EXT)) as out:
        if r.mode == "particles":
            p = ParticleFrame.read(job.upstream["simulate"].frame_path(f, ParticleFrame.EXT))
            pts = {o.name: (p.x[p.body == i], colour_for(o.material, i)) for i, o in enumerate(shot.objects)}
            px = r.height * shot.particle_spacing / shot.domain.size * 1.5
            renderer.particles(pts, px, out, label=label)
        else:
            material_of = {g: o.material for g, o in zip(shot.surface_groups(), shot.objects)}
            groups = SurfaceFrame.read(job.upstream["surface"].frame_path(f, SurfaceFrame.EXT)).groups
            meshes = {g: (d.vertices, d.faces, colour_for(material_of.get(g, g), i))
                      for i, (g, d) in enumerate(groups.items())}
            meshes |= _collider_meshes(shot, f)
            renderer.surfaces(meshes, out, label=label)


def finish(ctx: Context, results: list) -> dict:
    """In the client, after every frame's task: the movie, the contact sheet, and (unless a
    wedge variant) the copy to renders/<shot>/."""
    from mpmfx.render.frames import contact_sheet, write_movie

    shot, entry = ctx.shot, ctx.entry
    pngs = [entry.frame_path(f, FRAME_EXT) for f in entry.done_frames(FRAME_EXT)]
    movie = None
    if shot.render.movie and len(pngs) > 1:
        movie = write_movie(pngs, entry.root / f"{shot.shot.name}.mp4", fps=shot.shot.fps)
    sheet = contact_sheet(pngs, entry.root / "contact.png") if pngs else None
    if not ctx.publish:
        return {}
    out = publish(shot, pngs, [p for p in (movie, sheet) if p is not None])
    return {"published": str(out)}


# One renderer per process, reused for every frame it renders (creating a render window is the
# slow part): the serial path's, or a Dask worker's, for the set-up it last rendered (a wedge's
# variants of one shot share it).
_RENDERER: dict[str, object] = {}


def _renderer(job: FrameJob):
    from mpmfx.render.camera import default_camera
    from mpmfx.render.frames import FrameRenderer

    shot, r = job.shot, job.shot.render
    setup = dict(size=(r.width, r.height), camera=default_camera(shot),
                 domain=(shot.domain.origin, shot.domain.size), title=shot.shot.name)
    key = repr(setup)
    if key not in _RENDERER:
        close()
        _RENDERER[key] = FrameRenderer(**setup)
    return _RENDERER[key]


def close() -> None:
    """Close this process's renderer (the next frame makes a new one)."""
    for key in list(_RENDERER):
        _RENDERER.pop(key).close()


def _collider_meshes(shot: Shot, frame: int) -> dict:
    """Each collider posed at this frame's time, in a neutral grey, so the audience sees what hits."""
    from mpmfx.geometry.colliders import collider_mesh, keyframes
    from mpmfx.mpm.colliders import pose_matrix
    t = (frame - shot.shot.frame_start) / shot.shot.fps
    out = {}
    for col in shot.colliders:
        m = collider_mesh(col, resolve=shot.resolve, plane_size=2 * shot.domain.size)
        xf = pose_matrix(*keyframes(col), t)
        out[f"collider_{col.name}"] = (m.vertices @ xf[:3, :3].T + xf[:3, 3], m.faces, "#9aa0a8")
    return out


def publish(shot: Shot, pngs: list[Path], extras: list[Path]) -> Path:
    """Copy the frames, the movie and the contact sheet to renders/<shot>/ (in the working directory)."""
    out = Path("renders") / shot.shot.name
    out.mkdir(parents=True, exist_ok=True)
    for p in pngs:
        shutil.copyfile(p, out / p.name)
    for p in extras:
        shutil.copyfile(p, out / p.name)
    return out
