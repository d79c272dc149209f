"""Stage 3: each frame's particles become narrow-band level sets and meshes (world units).

Output `frames/NNNN.npz`: an `mpmfx.io.frames.SurfaceFrame` record, one `GroupSurface` per
surface group (a material, an object, or "all": `surface.group`): the mesh with vertex normals
and velocities, and the sparse level set as 8^3 leaves (its size follows the surface area, not
the domain), with velocity leaves and, with `surface.density` on, fog density leaves. The
leaves are kept only when export writes VDB (`export.vdb`), their one reader.
"""

from __future__ import annotations

import contextlib
import time
from concurrent.futures import ThreadPoolExecutor
from functools import partial

import numpy as np
import warp as wp

from mpmfx.config import Shot
from mpmfx.io.frames import GroupSurface, ParticleFrame, SurfaceFrame
from mpmfx.stages.base import Context, StageError, quiet_warp
from mpmfx.stages.parallel import FrameJob
from mpmfx.stages.writer import FrameWriter
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, GridTooLarge, SurfaceParams, surface_particles
from mpmfx.surface.pinned import host_buffer

NAME, VERSION, PER_FRAME, FRAME_EXT = "surface", 2, True, SurfaceFrame.EXT
CODE = ("mpmfx.stages.surface", "mpmfx.surface", "mpmfx.io.frames")
SURFACED = ("x", "v", "body")  # what the surfacer reads of a particle frame
GPU_WRITE_THREADS = 4  # frames deflated and written at once while the GPU surfaces the next
PINNED_READS = True  # on a GPU, particle frames are read into page-locked memory (read_particles)


def params(shot: Shot) -> dict:
    # The resolved surfacer parameters of each group, not the config section: a changed default
    # re-runs surface.
    resolved = {
        g: {k: getattr(v, "value", v) for k, v in vars(surface_params(shot, g)).items()}
        for g in sorted(set(shot.surface_groups()))
    }
    return {"surface": resolved, "groups": shot.surface_groups()}


def inputs(shot: Shot) -> dict[str, str]:
    return {}


def surface_params(shot: Shot, group: str):
    """The surfacer's parameters for surface group `group` (one of shot.surface_groups())."""
    s = shot.surface
    h = shot.particle_spacing
    # Default voxel: half the particle spacing, fine enough for a smooth render and ~10x cheaper
    # than the surfacer's own default (a quarter of the radius).
    return SurfaceParams(
        particle_radius=PARTICLE_RADIUS_PER_SPACING * h,
        radius_scale=s.radius_scale,
        voxel_size=s.voxel_size or 0.5 * h,
        dense_output=False,
        smooth_iters=s.smooth_iters,
        dilate=s.dilate,
        min_feature_particles=s.min_feature_particles,
        density=s.density,
        leaves=shot.export.vdb,  # the level set's leaves are for the VDB export, their one reader
        half_attributes=True,  # as the frame file stores them (SurfaceFrame._HALF)
        anisotropic=s.anisotropic,
        close_voids=s.close_voids,
        sharp_edges=shot.sharp_edges_for(group),
    )


def todo(ctx: Context) -> list[int]:
    return [f for f in ctx.frames if not ctx.entry.frame_path(f, FRAME_EXT).exists()]


def run(ctx: Context) -> dict:
    quiet_warp(ctx.device)
    # On a GPU a frame takes ~0.3 s here, less than a worker takes to start and load its kernels
    # (docs/scale-out.md): the default stays serial there; on the CPU, frames go to all cores.
    # Serial frames are read ahead and written behind on threads: at 10M particles on an H200
    # reading a frame takes ~50 ms, surfacing it 90-140 ms, deflating and writing it 80-100 ms.
    on_gpu = wp.get_device(ctx.device).is_cuda
    serial = partial(_pipelined, write_threads=write_threads(ctx.device))
    return finish(ctx, ctx.map_frames(frame, todo(ctx), desc="surface", auto=not on_gpu, serial=serial))


def write_threads(device: str | None) -> int:
    """Threads writing frames behind the surfacing: on a GPU a frame's deflate and write take about
    as long as its surfacing, and several frames are written at once."""
    return GPU_WRITE_THREADS if wp.get_device(device).is_cuda else 1


def finish(ctx: Context, results: list[dict]) -> dict:
    """In the client, after every frame's task (those made while simulate ran included): the
    manifest's extras."""
    done = results + ctx.followed
    out = {"this_run": {k: sum(r[k] for r in done) for k in ("vertices", "faces")}}
    split: dict[str, float] = {}
    for r in results:  # the frames of this process's own loop (`_pipelined`)
        for k, sec in r.get("seconds", {}).items():
            split[k] = split.get(k, 0.0) + sec
    if split:
        out["seconds_split"] = {k: round(sec, 3) for k, sec in split.items()}
    return out


def frame(job: FrameJob, f: int) -> dict:
    """Surface frame `f` into the entry (a task: runs on any worker); returns its mesh size."""
    surfaces, stats = make_surfaces(job, read_particles(job, f), f)
    surfaces.write(job.entry.frame_path(f, FRAME_EXT))
    return stats


def _pipelined(calls: list[tuple[FrameJob, int]], bar, *, write_threads: int) -> list[dict]:
    """The frames of `calls` surfaced here one after another, the next frame's particles read on
    a thread meanwhile and each frame's file written on `write_threads` threads
    (`mpmfx.stages.writer.FrameWriter`: frames surfaced before an error are still written).
    Each frame's stats hold "seconds": how long this loop waited for its read, surfaced it, and
    waited for a writer to take it."""
    out = []
    with (
        ThreadPoolExecutor(max_workers=1, thread_name_prefix="mpmfx-read") as reader,
        FrameWriter(write_threads) as writer,
    ):
        ahead = reader.submit(read_particles, *calls[0])
        for i, (job, f) in enumerate(calls):
            t0 = time.perf_counter()
            particles = ahead.result()
            if i + 1 < len(calls):
                ahead = reader.submit(read_particles, *calls[i + 1])
            t1 = time.perf_counter()
            surfaces, stats = make_surfaces(job, particles, f)
            del particles
            t2 = time.perf_counter()
            writer.submit(surfaces.write, job.entry.frame_path(f, FRAME_EXT))
            stats["seconds"] = {"read_wait": t1 - t0, "surface": t2 - t1, "writer_wait": time.perf_counter() - t2}
            out.append(stats)
            bar.update()
    return out


def read_particles(job: FrameJob, f: int) -> ParticleFrame:
    """Frame f's particles. On a GPU into page-locked memory, which the surfacer uploads in one
    DMA (pageable memory goes through the driver's staging: 243 MB of x and v at 10M)."""
    sim = job.upstream["simulate"]  # verified: a changed frame is redone by simulate, not surfaced
    alloc = partial(host_buffer, wp) if PINNED_READS and wp.get_device(job.device).is_cuda else None
    return sim.read(sim.frame_path(f, ParticleFrame.EXT), partial(ParticleFrame.read, fields=SURFACED, alloc=alloc))


def make_surfaces(job: FrameJob, p: ParticleFrame, f: int, *, turn=contextlib.nullcontext) -> tuple[SurfaceFrame, dict]:
    """(frame f's surfaces, one GroupSurface a surface group; its mesh size). turn(): held while
    the surfacer has the device (`mpmfx.stages.base.device_turn`); the host's share is outside it."""
    quiet_warp(job.device)
    shot = job.shot
    names = shot.surface_groups()
    groups = sorted(set(names))
    stats = {"vertices": 0, "faces": 0}
    group_of = np.asarray([groups.index(n) for n in names], np.int32)[p.body] if len(groups) > 1 else None
    out = {}
    for gi, g in enumerate(groups):
        sel = slice(None) if group_of is None else group_of == gi  # one group: a view, not a 240 MB copy at 10M
        x, v = p.x[sel], p.v[sel]
        try:
            with turn():
                res = surface_particles(x, v, surface_params(shot, g), device=job.device)
        except GridTooLarge as exc:  # the surfacer names its own parameter; the shot has a key for voxel_size
            raise StageError(
                f"{shot.source or shot.shot.name}: surface.voxel_size, frame {f}, group {g!r}: "
                f"{exc.detail} (--set surface.voxel_size=...)"
            ) from None
        m, ls = res.mesh, res.sparse
        leaves = {}
        if shot.export.vdb:  # the surfacer returned them (surface_params: leaves)
            leaves = dict(
                block_ijk=ls.block_ijk,
                blocks=ls.values,
                inside_ijk=ls.inside_ijk,
                # motion-blur vectors: half precision is plenty, and half the bytes
                vel_blocks=None if ls.velocity is None else ls.velocity.astype(np.float16),
                # 0..1 for a fog shader: float16's 5e-4 steps are invisible
                density_blocks=None if ls.density is None else ls.density.astype(np.float16),
            )
        out[g] = GroupSurface(
            vertices=m.vertices,
            faces=m.faces,
            normals=m.normals,
            velocities=m.velocities,
            voxel_size=ls.voxel_size,
            background=ls.background,
            **leaves,
        )
        stats["vertices"] += len(m.vertices)
        stats["faces"] += len(m.faces)
    return SurfaceFrame(out), stats
