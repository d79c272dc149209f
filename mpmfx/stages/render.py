"""Stage 5: PNG frames and an mp4 of the surfaces (or the particle debug look).

`render.engine = "cycles"`: Blender's Cycles renders the export stage's USD stage in a child
process (`mpmfx.render.cycles`), and the lit scene is saved as `<shot>.blend`; `"preview"`:
PyVista viewport captures of the surface frames.
Output in the cache entry: `frames/NNNN.png`, `<shot>.mp4`, `contact.png` (and `<shot>.blend`);
the runner then publishes them to `renders/<shot>/`, the folder artists look in (`mpmfx.publish`),
after every run, cached or not. Each frame's label names the --set overrides of its variant.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from mpmfx.config import RenderEngine, Shot
from mpmfx.io.frames import ParticleFrame, SurfaceFrame
from mpmfx.stages.base import Context, StageError

NAME, VERSION, PER_FRAME, FRAME_EXT = "render", 2, True, "png"
CODE = ("mpmfx.stages.render", "mpmfx.render", "mpmfx.io.frames", "mpmfx.geometry.colliders",
        "mpmfx.geometry.mesh", "mpmfx.mpm.colliders")


def params(shot: Shot) -> dict:
    from mpmfx.render.camera import default_camera, solver_floor
    out = {"render": shot.render.model_dump(mode="json"), "camera": default_camera(shot),
           "domain": shot.domain.model_dump(mode="json"), "materials": [o.material for o in shot.objects],
           "colliders": [c.model_dump(mode="json") for c in shot.colliders], "floor": solver_floor(shot),
           "title": title(shot)}
    if shot.render.engine is RenderEngine.CYCLES:
        from mpmfx.render.cycles import blender_version
        out["blender"] = blender_version()  # another Blender may shade differently
    return out


def title(shot: Shot) -> str:
    """The label burned into every frame: the shot and the overrides that made this variant."""
    return "  ".join([shot.shot.name, *(f"--set {o}" for o in shot.overrides)])


def inputs(shot: Shot) -> dict[str, str]:
    return {}


def run(ctx: Context) -> dict:
    from mpmfx.render.frames import contact_sheet, write_movie

    shot, entry = ctx.shot, ctx.entry
    todo = [f for f in ctx.frames if not entry.frame_path(f, FRAME_EXT).exists()]
    step, start = shot.render.frame_step, shot.shot.frame_start
    source = {f: start + (f - start) // step * step for f in todo}  # the frame each one shows
    render = sorted({s for s in source.values() if not entry.frame_path(s, FRAME_EXT).exists()})
    extras, timing = [], {}
    if shot.render.engine is RenderEngine.CYCLES:
        blend, timing = _cycles(ctx, render)
        extras.append(blend)
    else:
        _preview(ctx, render)
    for f, s in source.items():
        if f != s:  # held frame: the same picture, so the movie keeps the shot's timing
            _hold(entry.frame_path(s, FRAME_EXT), entry.frame_path(f, FRAME_EXT))
    pngs = [entry.frame_path(f, FRAME_EXT) for f in entry.done_frames(FRAME_EXT)]
    if shot.render.movie and len(pngs) > 1:
        extras.append(write_movie(pngs, entry.root / f"{shot.shot.name}.mp4", fps=shot.shot.fps))
    shown = [entry.frame_path(f, FRAME_EXT) for f in entry.done_frames(FRAME_EXT) if (f - start) % step == 0]
    if shown:
        extras.append(contact_sheet(shown, entry.root / "contact.png", scale=2 if shot.render.width > 640 else 1))
    return {"outputs": [str(p) for p in extras if p is not None and p.exists()], **timing}


def _cycles(ctx: Context, frames: list[int]) -> tuple[Path, dict]:
    """Cycles through Blender's own process; returns the saved .blend and the seconds per frame
    (wall, and CPU of all render threads: wall / CPU shows how much of the machine it had)."""
    from mpmfx.render.camera import VIEW_DIRECTION, default_camera, solver_box, solver_floor
    from mpmfx.render.cycles import CyclesError, run_job, write_job
    from mpmfx.render.looks import look_for
    shot, entry, r = ctx.shot, ctx.entry, ctx.shot.render
    blend = entry.root / f"{shot.shot.name}.blend"
    if not frames:
        return blend, {}
    usd = ctx.upstream["export"].root / "shot.usda"
    looks = {g: look_for([g, o.name, o.material], r.looks) for g, o in zip(shot.surface_groups(), shot.objects)}
    looks |= {o.name: look_for([o.name, o.material], r.looks) for o in shot.objects}
    cam = None
    if r.camera_position is not None:
        pos, look = default_camera(shot)
        cam = {"position": pos, "look_at": look}
    job = write_job(entry.root / "cycles_job.json", usd=usd, frames=frames, blend=blend,
                    outputs=[entry.frame_path(f, FRAME_EXT) for f in frames], width=r.width, height=r.height,
                    samples=r.samples, denoise=r.denoise, shutter=r.shutter, fps=shot.shot.fps,
                    mode=r.mode, looks=looks, floor_y=solver_floor(shot), domain_origin=shot.domain.origin,
                    domain_size=shot.domain.size, camera=cam, view_direction=VIEW_DIRECTION,
                    sun_elevation=r.sun_elevation, sun_rotation=r.sun_rotation, walls=solver_box(shot),
                    basin=r.basin, label=title(shot) if shot.overrides else "")
    entry.frames_dir.mkdir(parents=True, exist_ok=True)
    times = {}
    try:
        for f, wall, cpu in ctx.progress(run_job(job, log=entry.root / "cycles.log"), total=len(frames), desc="render"):
            times[f] = [wall, cpu]
    except CyclesError as exc:
        raise StageError(f"render (cycles): {exc}") from None
    return blend, {"cycles_seconds": times}


def _preview(ctx: Context, frames: list[int]) -> None:
    """PyVista viewport captures (the fast look) of the surfaces or particles."""
    from mpmfx.render.camera import default_camera, solver_floor
    from mpmfx.render.frames import FrameRenderer, colour_for
    shot, entry, r = ctx.shot, ctx.entry, ctx.shot.render
    renderer = FrameRenderer(size=(r.width, r.height), camera=default_camera(shot), floor=solver_floor(shot),
                             domain=(shot.domain.origin, shot.domain.size), title=title(shot))
    material_of = {g: o.material for g, o in zip(shot.surface_groups(), shot.objects)}
    try:
        for f in ctx.progress(frames, total=len(frames), desc="render"):
            label = f"frame {f}  t={(f - shot.shot.frame_start) / shot.shot.fps:.2f}s"
            if r.mode == "particles":
                p = ParticleFrame.read(ctx.upstream["simulate"].frame_path(f, ParticleFrame.EXT))
                pts = {o.name: (p.x[p.body == i], colour_for(o.material, i)) for i, o in enumerate(shot.objects)}
                px = r.height * shot.particle_spacing / shot.domain.size * 1.5
                renderer.particles(pts, px, entry.frame_path(f, FRAME_EXT), label=label)
            else:
                groups = SurfaceFrame.read(ctx.upstream["surface"].frame_path(f, SurfaceFrame.EXT)).groups
                meshes = {g: (d.vertices, d.faces, colour_for(material_of.get(g, g), i))
                          for i, (g, d) in enumerate(groups.items())}
                meshes |= _collider_meshes(shot, f)
                renderer.surfaces(meshes, entry.frame_path(f, FRAME_EXT), label=label)
    finally:
        renderer.close()


def _hold(src: Path, dst: Path) -> None:
    """dst shows the same picture as src (a hard link where the file system allows)."""
    tmp = dst.with_name(f".{dst.stem}.tmp.png")
    tmp.unlink(missing_ok=True)
    try:
        os.link(src, tmp)
    except OSError:
        shutil.copyfile(src, tmp)
    tmp.replace(dst)


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

