"""Stage 5: PNG frames and an mp4 of the surfaces (or the particle debug look).

`render.engine = "cycles"`: Blender's Cycles renders the export stage's USD stage in a child
process (`mpmfx.render.cycles`; given two or more Dask workers, one child a chunk of frames on
each, `chunks`), and the lit scene is saved as `<shot>.blend`; `"preview"`:
PyVista viewport captures of the surface frames.
Output in the cache entry: `frames/NNNN.png`, `<shot>.mp4`, `contact.png` (and `<shot>.blend`);
the runner then publishes them to `renders/<shot>/`, the folder artists look in (`mpmfx.publish`),
after every run, cached or not. Each frame's label names the --set overrides of its variant.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from mpmfx import checksum
from mpmfx.cache import atomic_path
from mpmfx.config import RenderEngine, Shot
from mpmfx.geometry.colliders import collider_mesh, keyframes
from mpmfx.io.frames import ParticleFrame, SurfaceFrame
from mpmfx.mpm.colliders import pose_matrix
from mpmfx.publish import PUBLISHED, publish_name
from mpmfx.render.camera import VIEW_DIRECTION, default_camera, frame_box, render_camera, solver_box, solver_floor
from mpmfx.render.cycles import CyclesError, blender_version, run_job, write_job
from mpmfx.render.frames import FrameRenderer, colour_for, write_movie
from mpmfx.render.looks import PROP_LOOKS, look_for
from mpmfx.render.sheets import contact_sheet, evenly_spaced
from mpmfx.stages.base import Context, StageError
from mpmfx.stages.colliders import animated_collider, collider_geometry, collider_key
from mpmfx.stages.names import surface_looks, usd_names
from mpmfx.stages.parallel import CORES_ENV, FrameJob, task_key

CHUNK = 16  # at most this many frames to one Blender process when frames are spread over workers

NAME, VERSION, PER_FRAME, FRAME_EXT = "render", 2, True, "png"
CODE = (
    "mpmfx.stages.render",
    "mpmfx.stages.names",
    "mpmfx.render",
    "mpmfx.io.frames",
    "mpmfx.stages.colliders",
    "mpmfx.geometry.colliders",
    "mpmfx.geometry.animated",
    "mpmfx.geometry.mesh",
    "mpmfx.mpm.colliders",
)


def params(shot: Shot) -> dict:
    out = {
        "render": shot.render.model_dump(mode="json"),
        "camera": default_camera(shot),
        "domain": shot.domain.model_dump(mode="json"),
        "materials": [o.material for o in shot.bodies],
        "colliders": [collider_key(c) for c in shot.colliders],
        "floor": solver_floor(shot),
        "title": title(shot),
    }
    if shot.render.engine is RenderEngine.CYCLES:
        out["blender"] = blender_version()  # another Blender may shade differently
        out["blend_usd_root"] = blend_usd_root(shot)
    elif shot.render.frame_step > 1:
        out["every_frame"] = True  # not an entry whose held frames carry another frame's label
    return out


def blend_usd_root(shot: Shot) -> str:
    """Where the .blend finds the USD stage once published to renders/<name>/: published/<name>,
    relative to the .blend (Blender's `//`), so moving the whole project folder keeps it playing
    (an absolute path would break; the cache path it was rendered from is not what artists get)."""
    return f"//../../{PUBLISHED.as_posix()}/{publish_name(shot)}"


def title(shot: Shot) -> str:
    """The label burned into every frame: the shot and the overrides that made this variant."""
    return "  ".join([shot.shot.name, *(f"--set {o}" for o in shot.overrides)])


def inputs(shot: Shot) -> dict[str, str]:
    return {}


def frame_step(shot: Shot) -> int:
    """Every how many frames one is drawn: `render.frame_step` in Cycles; the preview draws
    every frame (under a second each), so each frame's burned-in label is its own."""
    return shot.render.frame_step if shot.render.engine is RenderEngine.CYCLES else 1


def todo(ctx: Context) -> list[int]:
    """The frames to draw: of the missing ones, those `frame_step` shows (the others hold)."""
    step, start = frame_step(ctx.shot), ctx.shot.shot.frame_start
    shown = {start + (f - start) // step * step for f in ctx.frames}
    return sorted(f for f in shown if not ctx.entry.frame_path(f, FRAME_EXT).exists())


def run(ctx: Context) -> dict:
    if ctx.shot.render.engine is RenderEngine.CYCLES:
        workers = ctx.executor.spread() if ctx.executor is not None else 1
        frames = todo(ctx)
        if workers < 2 or len(frames) < 2:
            # One Blender process for every frame: it imports the USD stage once, and Cycles
            # already uses every core of this machine.
            return finish(ctx, [_cycles(ctx.job(), frames, progress=ctx.progress)])
        return finish(ctx, _cycles_on_workers(ctx, frames, workers))
    try:
        return finish(ctx, ctx.map_frames(frame, todo(ctx), desc="render"))
    finally:
        close()  # the serial path's renderer; a worker's ends with the worker


def frame(job: FrameJob, f: int) -> dict:
    """Draw frame `f` into the entry (a task: runs on any worker, e.g. a wedge's)."""
    if job.shot.render.engine is RenderEngine.CYCLES:
        return _cycles(job, [f])
    _preview(job, f)
    return {}


def finish(ctx: Context, results: list[dict]) -> dict:
    """In the client, after every frame's task: held frames, the movie, the contact sheet; the
    runner publishes them (and the .blend) to renders/<shot>/."""
    shot, entry = ctx.shot, ctx.entry
    step, start = frame_step(shot), shot.shot.frame_start
    for f in ctx.frames:
        src = start + (f - start) // step * step
        if f != src and not entry.frame_path(f, FRAME_EXT).exists():
            _hold(entry.frame_path(src, FRAME_EXT), entry.frame_path(f, FRAME_EXT))
    extras = [entry.root / f"{shot.shot.name}.blend"]
    pngs = [entry.frame_path(f, FRAME_EXT) for f in entry.done_frames(FRAME_EXT)]
    if shot.render.movie and len(pngs) > 1:
        extras.append(write_movie(pngs, entry.root / f"{shot.shot.name}.mp4", fps=shot.shot.fps))
    shown = {f: entry.frame_path(f, FRAME_EXT) for f in entry.done_frames(FRAME_EXT) if (f - start) % step == 0}
    if shown:
        extras.append(contact_sheet(shown, entry.root / "contact.png"))
    seconds = {f: t for r in results for f, t in r.get("cycles_seconds", {}).items()}
    return {
        "outputs": [str(p) for p in extras if p is not None and p.exists()],
        **({"cycles_seconds": seconds} if seconds else {}),
    }


def shown_bounds(shot: Shot, upstream: dict[str, Path], frames: list[int]):
    """(lo, hi) world corners (m, (3,) each) of what a render of `frames` shows: the surfaces
    (the particles in particles mode) and the colliders, down to the floor, over at most 12 of
    the frames, as Cycles frames its own camera. upstream: stage name -> entry folder. None
    where nothing is shown."""
    boxes = []
    for f in evenly_spaced(sorted(frames), 12):
        if shot.render.mode == "particles":
            boxes.append(ParticleFrame.read(upstream["simulate"] / "frames" / f"{f:04d}.npz").x)
        else:
            groups = SurfaceFrame.read(upstream["surface"] / "frames" / f"{f:04d}.npz").groups
            boxes += [g.vertices for g in groups.values()]
        boxes += [v for v, _, _ in _collider_meshes(shot, f).values()]
    boxes = [np.asarray(b, float).reshape(-1, 3) for b in boxes if len(b)]
    if not boxes:
        return None
    lo, hi = np.min([b.min(0) for b in boxes], axis=0), np.max([b.max(0) for b in boxes], axis=0)
    lo[1] = min(lo[1], solver_floor(shot))  # keep the ground contact in the picture
    return lo, hi


def framing_camera(shot: Shot, lo, hi) -> Shot:
    """`shot` with a render camera that frames the box [lo, hi] (m) as Cycles' automatic camera
    would: a wedge frames every variant through one camera, so framing does not shift."""
    pos, look = frame_box(lo, hi, direction=VIEW_DIRECTION, aspect=shot.render.width / shot.render.height)
    return shot.model_copy(
        update={"render": shot.render.model_copy(update={"camera_position": pos, "camera_look_at": look})}
    )


def chunks(frames: list[int], workers: int, most: int = CHUNK) -> list[list[int]]:
    """`frames` dealt into Blender jobs: at least one a worker, at most `most` frames each,
    strided (every n-th frame) so each job's frames spread over the shot: the heavy end of a
    shot (the splash) is shared by every worker, not one worker's. Every chunk non-empty."""
    n = min(len(frames), max(workers, -(-len(frames) // most)))
    return [frames[i::n] for i in range(n)] if frames else []


def _cycles_on_workers(ctx: Context, frames: list[int], workers: int) -> list[dict]:
    """The frames as Blender jobs on the Dask workers (`chunks`), each reading the same USD
    stage; the first job saves the .blend. A failed job is one line naming its frames and worker;
    the frames others finished stay, and a re-run renders only the missing ones."""
    job, parts = ctx.job(), chunks(frames, workers)
    labels = [f"render (cycles) frames {_span(p)} of {ctx.shot.shot.name}" for p in parts]
    keys = [f"{task_key(ctx.entry)}-cycles-{p[0]:04d}-{len(p)}" for p in parts]
    args = [(job, p, i == 0) for i, p in enumerate(parts)]
    return ctx.executor.calls(_cycles_chunk, args, keys=keys, labels=labels, desc="render", quiet=ctx.quiet)


def _span(frames: list[int]) -> str:
    """Frames for a message: '1, 3, 5' or, for many, '1, 3, ... 31 (16 frames)'."""
    if len(frames) <= 4:
        return ", ".join(map(str, frames))
    return f"{frames[0]}, {frames[1]}, ... {frames[-1]} ({len(frames)} frames)"


def _cycles_chunk(job: FrameJob, frames: list[int], save_blend: bool) -> dict:
    """On a worker: one Blender process for `frames`, on the worker's share of the cores (a
    LocalCluster's $MPMFX_WORKER_CORES; a farm worker, alone on its host, uses every core)."""
    threads = int(os.environ.get(CORES_ENV) or 0)
    return _cycles(job, frames, name=f"cycles_{frames[0]:04d}_{len(frames)}", blend=save_blend, threads=threads)


def _cycles(
    job: FrameJob,
    frames: list[int],
    *,
    progress=lambda it, **kw: it,
    name: str | None = None,
    blend: bool | None = None,
    threads: int = 0,
) -> dict:
    """Cycles through Blender's own process; saves the lit scene as `<shot>.blend` and returns
    the seconds per frame (wall, and CPU of all render threads: wall / CPU shows how much of the
    machine it had). name: of its job and log files; blend: whether it saves the .blend (None:
    a whole render does, a one-frame job while none is there); threads: Cycles' (0: all cores)."""
    shot, entry, r = job.shot, job.entry, job.shot.render
    if not frames:
        return {}
    # looks by the stage's prim names: each surface, each object's particles, the props
    names = usd_names(shot)
    looks = {names.surfaces[g]: look for g, look in surface_looks(shot).items()}
    looks |= {names.particles[o.name]: look_for([o.name, o.material], r.looks) for o in shot.bodies}
    looks |= {prop: r.looks.get(prop, look) for prop, look in PROP_LOOKS.items()}
    collider_looks = {c.name: r.looks.get(c.name, "collider") for c in shot.colliders}
    # the camera the export framed and wrote into the USD: the render looks through the same one
    cam = (job.upstream["export"].manifest() or {}).get("camera") or render_camera(shot)
    name = name or (f"cycles_{frames[0]:04d}" if len(frames) == 1 else "cycles")  # a wedge's tasks: one job each
    path = entry.root / f"{shot.shot.name}.blend"
    if blend is None:
        # one .blend an entry: a wedge's per-frame tasks (each a job) save it only while it is
        # missing; two that race write the same scene through temp names of their own
        blend = len(frames) > 1 or not path.exists()
    spec = write_job(
        entry.root / f"{name}_job.json",
        usd=job.upstream["export"].root / "shot.usda",
        frames=frames,
        blend=path if blend else None,
        outputs=[entry.frame_path(f, FRAME_EXT) for f in frames],
        width=r.width,
        height=r.height,
        samples=r.samples,
        denoise=r.denoise,
        device=r.device,
        collider_looks=collider_looks,
        shutter=r.shutter,
        fps=shot.shot.fps,
        mode=r.mode,
        looks=looks,
        floor_y=solver_floor(shot),
        domain_origin=shot.domain.origin,
        domain_size=shot.domain.size,
        camera=cam,
        sun_elevation=r.sun_elevation,
        sun_rotation=r.sun_rotation,
        walls=solver_box(shot),
        basin=r.basin,
        label=title(shot) if shot.overrides else "",
        blend_usd_root=blend_usd_root(shot),
        threads=threads,
    )
    entry.frames_dir.mkdir(parents=True, exist_ok=True)
    times = {}
    try:
        for f, wall, cpu in progress(run_job(spec, log=entry.root / f"{name}.log"), total=len(frames), desc="render"):
            checksum.record(entry.frame_path(f, FRAME_EXT))  # Blender wrote it: its digest, as written
            times[f] = [wall, cpu]
    except CyclesError as exc:
        raise StageError(f"render (cycles): {exc}") from None
    return {"cycles_seconds": times}


# One preview renderer per process, reused for every frame it draws (creating a render window is
# the slow part): the serial path's, or a Dask worker's, for the set-up it last drew (a wedge's
# variants of one shot share it).
_RENDERER: dict[str, object] = {}


def _preview(job: FrameJob, f: int) -> None:
    """PyVista viewport capture (the fast look) of frame f's surfaces or particles."""
    shot, r = job.shot, job.shot.render
    setup = dict(
        size=(r.width, r.height),
        camera=default_camera(shot),
        floor=solver_floor(shot),
        domain=(shot.domain.origin, shot.domain.size),
        title=title(shot),
    )
    if repr(setup) not in _RENDERER:
        close()
        _RENDERER[repr(setup)] = FrameRenderer(**setup)
    renderer = _RENDERER[repr(setup)]
    label = f"frame {f}  t={(f - shot.shot.frame_start) / shot.shot.fps:.2f}s"
    # The renderer writes through its own temp name; this one is unique per writer, so two
    # workers drawing one frame never share a temp file, and the frame is complete or absent.
    sim, surf = job.upstream["simulate"], job.upstream["surface"]  # verified reads: a changed frame is redone
    with atomic_path(job.entry.frame_path(f, FRAME_EXT), checksum=True) as out:
        if r.mode == "particles":
            p = sim.read(sim.frame_path(f, ParticleFrame.EXT), ParticleFrame.read)
            pts = {o.name: (p.x[p.body == i], colour_for(o.material, i)) for i, o in enumerate(shot.bodies)}
            px = r.height * shot.particle_spacing / shot.domain.size * 1.5
            renderer.particles(pts, px, out, label=label)
        else:
            material_of = {g: o.material for g, o in zip(shot.surface_groups(), shot.bodies)}
            groups = surf.read(surf.frame_path(f, SurfaceFrame.EXT), SurfaceFrame.read).groups
            meshes = {
                g: (d.vertices, d.faces, colour_for(material_of.get(g, g), i))
                for i, (g, d) in enumerate(groups.items())
            }
            meshes |= _collider_meshes(shot, f)
            renderer.surfaces(meshes, out, label=label)


def close() -> None:
    """Close this process's preview renderer (the next frame makes a new one)."""
    for key in list(_RENDERER):
        _RENDERER.pop(key).close()


def _hold(src: Path, dst: Path) -> None:
    """dst shows the same picture as src (a hard link where the file system allows)."""
    tmp = dst.with_name(f".{dst.stem}.tmp.png")
    tmp.unlink(missing_ok=True)
    try:
        os.link(src, tmp)
    except OSError:
        shutil.copyfile(src, tmp)
    tmp.replace(dst)
    checksum.record(dst)


def _collider_meshes(shot: Shot, frame: int) -> dict:
    """Each collider posed at this frame's time, in a neutral grey, so the audience sees what hits."""
    t = (frame - shot.shot.frame_start) / shot.shot.fps
    out = {}
    for i, col in enumerate(shot.colliders):
        if col.animated:
            _, pts, faces = animated_collider(shot, i)
            out[f"collider_{col.name}"] = (pts[frame - shot.shot.frame_start], faces, "#9aa0a8")
            continue
        geom = collider_geometry(col)
        m = collider_mesh(geom, resolve=shot.resolve, plane_size=2 * shot.domain.size)
        xf = pose_matrix(*keyframes(geom), t)
        out[f"collider_{col.name}"] = (m.vertices @ xf[:3, :3].T + xf[:3, 3], m.faces, "#9aa0a8")
    return out
