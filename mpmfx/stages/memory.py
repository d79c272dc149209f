"""The memory a shot needs, estimated before voxelise starts, against what the machine has.

An estimate from array counts, not an allocator's tally: each figure below says which arrays
it counts. The need is the largest stage's, except that surface follows simulate frame by frame
(`mpmfx.stages.follow`): then the solver's and the surfacer's buffers are held at once, on the
device and on the host.
A shot over the memory available (host: /proc/meminfo MemAvailable; a CUDA device: Warp's free
memory) is refused as bad input naming the keys that shrink it, before anything is written.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from mpmfx.config import Shot, ShotError
from mpmfx.geometry.mesh import MeshError, load_mesh, transform_mesh
from mpmfx.geometry.thickness import measuring_lattice
from mpmfx.meminfo import host_available
from mpmfx.mpm.emission import device_bytes
from mpmfx.mpm.state import SceneFlags
from mpmfx.stages.base import quiet_warp

# Voxelise, a candidate point of an object's fine lattice (bounding box cells x ppc): its
# inside flag (1), argwhere index (3 int64: 24), jitter (3 float64: 24), position (3 float64:
# 24), and the seed record's x, v, volume, body, birth (24 + 24 + 8 + 4 + 8) for the kept ones.
VOXELISE_BYTES_PER_POINT = 1 + 24 + 24 + 24 + 68
# Simulate, host side per particle beyond the solver's arrays (mpm.emission.device_bytes): the
# seed record read back (68, as above), the frame being written and the one read back beside
# it (ParticleFrame: x, v 12 + 12, id, material, body 4 x 3, Jp, J 4 + 4: 44, twice), and a
# checkpoint's host copy (x, v, C, F 12 + 12 + 36 + 36, Jp, J, alive 12, the six constants 24:
# 132).
WRITER_BYTES_PER_PARTICLE = 68 + 2 * 44 + 132
# Surface, per particle: positions, velocities, their grid and sorted copies (4 x 12), the bin
# order and cell (4 + 4); per voxel of an active block: raw field, weights, velocity (4 + 4 +
# 12), the edge flags and the smoothing's second level set (4 + 4), the flood and component
# labels (4 + 4), marching cubes' vertex slots (amortised 8). At most every voxel within a
# particle's spacing is active (the default voxel, half the spacing: 8 a particle).
SURFACE_BYTES_PER_PARTICLE = 4 * 12 + 8
SURFACE_BYTES_PER_VOXEL = 20 + 8 + 8 + 8
SURFACE_BYTES_PER_BLOCK = 16  # the block map over the particles' box: index, class, counts (8^3 voxels)
# A frame's mesh on the host, per particle: at the default voxel a body of particles has about
# 0.3 surface vertices a particle (hero_castle at 10M particles: 0.32), thin or splashing ones
# more; bounded at 0.6 vertices (position, normal, velocity 36 B) and twice as many faces (24 B).
MESH_BYTES_PER_PARTICLE = int(0.6 * (36 + 2 * 12))
# Surface and export following simulate (overlap) hold, beside the two stages' own buffers: the
# particle frame being surfaced (44 as above, of which the stage reads x, v, body: 28), the surface frames that GPU_WRITE_THREADS threads
# deflate and write behind plus the one being made, and export's frame read and its USD arrays.
FOLLOW_SURFACE_FRAMES = 4 + 1
FOLLOW_BYTES_PER_PARTICLE = 44 + FOLLOW_SURFACE_FRAMES * MESH_BYTES_PER_PARTICLE + 2 * MESH_BYTES_PER_PARTICLE
# Measured, not counted: on one H200, hero_castle's overlapped stages peaked at 4.21 and 6.52 GB
# of host at 2.64M and 5.16M particles (`mpmfx bench shot`, the peak after voxelise): 917 B a
# particle over 1.8 GB. The arrays counted above make 640 B a particle; the rest is what the
# allocator keeps between frames for the many threads that read, deflate and write them. The
# 1.8 GB is the GPU process itself (CUDA's context, Warp's modules, page-locked pools). At 10.1M
# particles this gives 11.1 GB, above the 8.7 GB that run peaked at: an upper bound.
CUDA_PROCESS_BYTES = 1_800_000_000
FOLLOW_ALLOCATOR_BYTES_PER_PARTICLE = 280
# Voxelise's five-cell thickness check (per solid object, one at a time) on its raster of at
# most MAX_RASTER_VOXELS: distance transforms, labels and the subdivided mesh. Not counted from
# arrays but measured (peak RSS over the imports, 2-core CPU, assets/sand_column.obj at
# grid_n 40, 60, 80, 160: 118k, 368k, 759k, 1.5M raster voxels took 211, 303, 795, 951 MB);
# this bound is over each of them.
THICKNESS_BYTES = 100_000_000
THICKNESS_BYTES_PER_VOXEL = 1_100
# The process before any array: Python, Warp, trimesh, SciPy, PyVista imported and Warp started
# (measured peak RSS, 2-core CPU: 322 MB).
PROCESS_BYTES = 330_000_000


@dataclass
class Need:
    """Bytes each stage needs at its peak on the host and on the device; `particles` counted."""

    particles: int
    host: dict[str, int] = field(default_factory=dict)
    device: dict[str, int] = field(default_factory=dict)

    def line(self, *, host_free: int | None, device_free: int | None) -> str:
        host = max(self.host.values(), default=0)
        parts = ", ".join(f"{k} {_gb(v)}" for k, v in self.host.items())
        text = f"memory: ~{_gb(host)} host at the peak ({parts}; {self.particles:,} particles)"
        if self.device:
            text += f", ~{_gb(max(self.device.values()))} device"
        if host_free is not None:
            text += f"; {_gb(host_free)} host available"
        if device_free is not None:
            text += f", {_gb(device_free)} device free"
        return text


def _gb(b: int) -> str:
    return f"{b / 1e9:.1f} GB" if b >= 1e8 else f"{b / 1e6:.0f} MB"


def need(shot: Shot, counted: Counts, *, cuda: bool, overlap: bool = False) -> Need:
    """The estimate for what `counted` says (bytes; see the figures above), each stage's peak
    with the process's own PROCESS_BYTES on the host. cuda: the solver and surfacer run on a GPU;
    overlap: surface follows simulate (both stages' buffers at once, as "simulate + surface")."""
    n = counted.particles
    flags = SceneFlags(snow=True, sand=True, water=True)  # every branch's arrays: an upper bound
    solver = device_bytes(n, flags, shot.domain.grid_n, deterministic=shot.solver.deterministic, births=True, gpu=cuda)
    surface = surface_bytes(shot, n)
    out = Need(n)
    if counted.candidates or counted.raster:  # (voxelise cached: nothing to voxelise)
        thickness = THICKNESS_BYTES + counted.raster * THICKNESS_BYTES_PER_VOXEL if counted.raster else 0
        out.host["voxelise"] = PROCESS_BYTES + counted.candidates * VOXELISE_BYTES_PER_POINT + thickness
    writer = n * WRITER_BYTES_PER_PARTICLE
    if cuda:
        out.device["simulate"], out.device["surface"] = solver, surface
        out.host["simulate"] = CUDA_PROCESS_BYTES + writer
        out.host["surface"] = CUDA_PROCESS_BYTES + n * SURFACE_BYTES_PER_PARTICLE
    else:
        out.host["simulate"], out.host["surface"] = PROCESS_BYTES + solver + writer, PROCESS_BYTES + surface
    if overlap:
        if cuda:
            out.device["simulate + surface"] = out.device.pop("simulate") + out.device.pop("surface")
        followers = n * (FOLLOW_BYTES_PER_PARTICLE + (FOLLOW_ALLOCATOR_BYTES_PER_PARTICLE if cuda else 0))
        one_process = CUDA_PROCESS_BYTES if cuda else PROCESS_BYTES  # counted once, not per stage
        out.host["simulate + surface"] = out.host.pop("simulate") + out.host.pop("surface") - one_process + followers
    return out


def largest(shot: Shot, *, cuda: bool, overlap: bool, host_free: int, device_free: int | None) -> tuple[int, dict]:
    """(the most particles `shot` fits in host_free and device_free bytes, bytes a particle of
    each stage's peak: {"host": {stage: B}, "device": {stage: B}}). The estimate is linear in
    the particles (the grid and the process are the fixed part)."""
    fixed, per = (need(shot, Counts(n), cuda=cuda, overlap=overlap) for n in (0, 10**6))
    slope = {
        w: {k: (getattr(per, w)[k] - getattr(fixed, w)[k]) / 10**6 for k in getattr(per, w)} for w in ("host", "device")
    }
    fits = []
    for where, free in (("host", host_free), ("device", device_free)):
        for k, b in slope[where].items():
            if free is not None and b > 0:
                fits.append(int((free - getattr(fixed, where)[k]) / b))
    return max(0, min(fits)), slope


def surface_bytes(shot: Shot, particles: int) -> int:
    """The surfacer's peak for one frame of `particles` (upper bound: every particle's own
    voxels active, the block map over the whole domain)."""
    h = shot.particle_spacing
    voxel = shot.surface.voxel_size or 0.5 * h
    blocks = math.ceil(shot.domain.size / voxel / 8 + 2) ** 3
    per_particle_voxels = max((h / voxel) ** 3, 1.0)
    return int(
        particles * (SURFACE_BYTES_PER_PARTICLE + per_particle_voxels * SURFACE_BYTES_PER_VOXEL)
        + blocks * SURFACE_BYTES_PER_BLOCK
    )


@dataclass
class Counts:
    """What a shot's memory follows: particles (simulated), candidates (lattice points voxelise
    tests) and raster (the largest thickness-check raster of a solid object, voxels)."""

    particles: int
    candidates: int = 0
    raster: int = 0


def counts(shot: Shot) -> Counts:
    """Counts before voxelising: each object's lattice is its bounding box (inside the domain) at
    ppc points a cell, which bounds the particles it keeps; each emitter's particles are its
    volume emitted over the particle volume. ShotError naming the object for a mesh that cannot
    be loaded (bad input, before anything is written)."""
    dom, ppc = shot.domain, shot.voxelise.ppc
    dx = dom.size / dom.grid_n
    lo_dom, hi_dom = np.asarray(dom.origin, float), np.asarray(dom.origin, float) + dom.size
    out = Counts(0)
    for obj, fluid in zip(shot.objects, shot.fluid_objects()):
        try:
            mesh = transform_mesh(
                load_mesh(shot.resolve(obj.mesh), prim_path=obj.prim_path),
                translate=obj.translate,
                rotate_deg=obj.rotate,
                scale=obj.scale,
            )
        except MeshError as exc:  # the asset: bad input, refused before anything is written
            raise ShotError(f"objects.{obj.name}: {exc}") from None
        lo, hi = np.clip(mesh.bounds[0], lo_dom, hi_dom), np.clip(mesh.bounds[1], lo_dom, hi_dom)
        out.candidates += int(np.prod(np.ceil((hi - lo) / dx) + 1)) * ppc
        if not fluid:  # the thickness check is for solids (stages/voxelise.py)
            out.raster = max(out.raster, math.prod(measuring_lattice(mesh, dx).shape))
    emitted = sum(e.rate * (e.end_time - e.start_time) for e in shot.emitters) / (dx**3 / ppc)
    out.particles = out.candidates + int(emitted)
    return out


def device_free(device: str | None) -> int | None:
    """Free memory of the CUDA device a run uses (None on the CPU or where Warp cannot say)."""
    quiet_warp()  # no CUDA-driver warning on a CPU-only machine
    try:
        d = wp.get_device(device or "cuda") if wp.is_cuda_available() else None
        return int(d.free_memory) if d is not None and d.is_cuda else None
    except (RuntimeError, ValueError, AttributeError):
        return None


def check(shot: Shot, counted: Counts, *, device: str | None, quiet: bool = False, overlap: bool = False) -> Need:
    """Print the estimate in one line; raise ShotError (exit 2) naming the keys to change when
    it exceeds the host's available memory or the device's free memory. overlap: surface will
    follow simulate (`need`)."""
    free_dev = device_free(device) if device != "cpu" else None
    est = need(shot, counted, cuda=free_dev is not None, overlap=overlap)
    free_host = host_available()
    if not quiet:
        print(f"[run] {est.line(host_free=free_host, device_free=free_dev)}", file=sys.stderr)
    over = []
    if free_host is not None and max(est.host.values()) > free_host:
        over.append(("host", max(est.host, key=est.host.get), max(est.host.values()), free_host))
    if free_dev is not None and max(est.device.values()) > free_dev:
        over.append(("device", max(est.device, key=est.device.get), max(est.device.values()), free_dev))
    if over:
        where, stage, b, free = over[0]
        raise ShotError(
            f"{shot.source or shot.base_dir}: this shot needs ~{_gb(b)} of {where} memory in {stage} "
            f"(domain.grid_n = {shot.domain.grid_n}: {(shot.domain.grid_n + 1) ** 3:,} grid nodes; "
            f"{counted.particles:,} particles at voxelise.ppc = {shot.voxelise.ppc}; surface.voxel_size = "
            f"{shot.surface.voxel_size or 'default'}), over the {_gb(free)} available: lower domain.grid_n, "
            f"voxelise.ppc or the emitters' rates, or raise surface.voxel_size"
        )
    return est
