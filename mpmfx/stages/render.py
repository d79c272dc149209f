"""Stage 5: PNG frames and an mp4 of the surfaces (or the particle debug look).

Output in the cache entry: `frames/NNNN.png`, `<shot>.mp4` and `contact.png`; the runner then
publishes them to `renders/<shot>/`, the folder artists look in (`mpmfx.publish`), after every
run, cached or not. Each frame's burned-in label names the --set overrides of its variant.
"""
from __future__ import annotations

from mpmfx.config import Shot
from mpmfx.io.frames import ParticleFrame, SurfaceFrame
from mpmfx.stages.base import Context

NAME, VERSION, PER_FRAME, FRAME_EXT = "render", 1, True, "png"
CODE = ("mpmfx.stages.render", "mpmfx.render", "mpmfx.io.frames", "mpmfx.geometry.colliders",
        "mpmfx.geometry.mesh", "mpmfx.mpm.colliders")


def params(shot: Shot) -> dict:
    from mpmfx.render.camera import default_camera
    return {"render": shot.render.model_dump(mode="json"), "camera": default_camera(shot),
            "domain": shot.domain.model_dump(mode="json"), "materials": [o.material for o in shot.objects],
            "colliders": [c.model_dump(mode="json") for c in shot.colliders], "title": title(shot)}


def title(shot: Shot) -> str:
    """The label burned into every frame: the shot and the overrides that made this variant."""
    return "  ".join([shot.shot.name, *(f"--set {o}" for o in shot.overrides)])


def inputs(shot: Shot) -> dict[str, str]:
    return {}


def run(ctx: Context) -> dict:
    from mpmfx.render.camera import default_camera
    from mpmfx.render.frames import FrameRenderer, colour_for, contact_sheet, write_movie

    shot, entry = ctx.shot, ctx.entry
    r = shot.render
    todo = [f for f in ctx.frames if not entry.frame_path(f, FRAME_EXT).exists()]
    renderer = FrameRenderer(size=(r.width, r.height), camera=default_camera(shot),
                             domain=(shot.domain.origin, shot.domain.size), title=title(shot))
    material_of = {g: o.material for g, o in zip(shot.surface_groups(), shot.objects)}
    try:
        for f in ctx.progress(todo, total=len(todo), desc="render"):
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
    pngs = [entry.frame_path(f, FRAME_EXT) for f in entry.done_frames(FRAME_EXT)]
    movie = None
    if r.movie and len(pngs) > 1:
        movie = write_movie(pngs, entry.root / f"{shot.shot.name}.mp4", fps=shot.shot.fps)
    sheet = contact_sheet(pngs, entry.root / "contact.png") if pngs else None
    return {"movie": str(movie) if movie else None, "contact_sheet": str(sheet) if sheet else None}


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

