"""The surfacers `mpmfx bench surface` compares against, run on the same particles.

- splashsurf (PyPI `pysplashsurf`, CPU, Rust + rayon): SPH colour field + marching cubes.
- Newton's particle surfacer (`newton.geometry.ParticleSurface`, Warp; Yu & Turk 2010
  anisotropic kernels when `anisotropic`): density splatting on a sparse volume + marching cubes.

Each runner takes (n, 3) positions in metres and the particle spacing h (m), runs one warm-up
call (compilation, allocator and thread-pool start-up), then returns the median wall time of
`repeats` calls with the last call's mesh. Their particle radius is half the spacing, h / 2
(PEER_RADIUS_PER_SPACING): their models read it as the particle's size (splashsurf's rest
volume, Newton's splat volume (2 r)^3 = h^3), and their settings below were tuned at it. Ours
(mpmfx.surface.PARTICLE_RADIUS_PER_SPACING, 0.6 h) is an offset of our level set, another
quantity; giving the peers 0.6 h would only inflate their densities.

pysplashsurf and newton (optional) are imported inside the runners, and a missing one raises
ImportError that says what to pip install.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import warp as wp

from mpmfx.threads import usable_cores

PEER_RADIUS_PER_SPACING = 0.5
"""The peers' particle radius in units of the spacing h (see the module docstring)."""

PEERS = ("splashsurf", "newton", "newton-aniso")
"""Peer names the bench accepts (`--peers`)."""

SPLASHSURF_PIP = "pip install pysplashsurf==0.14.1.0"
NEWTON_PIP = "pip install newton==1.8.0"

# Each peer's settings for its best accuracy on these samples.
# splashsurf: (smoothing length, cube) in multiples of r, per sampling. At smoothing length 2r
# random samples leave voids that become hundreds of interior bubble surfaces and -16 %
# volume; 3r restores the volume, but bubbles remain (200k: 1325 pieces at 2r, 395 at 3r).
# Newton: (voxel, kernel_radius) in multiples of h. Both keep kernel_radius 3h, Newton's
# default at voxel h: at voxel h/2 its default (3 voxels = 1.5h) finds fewer than the 25
# neighbours WPCA needs on a lattice, so most kernels stay isotropic (measured on the CPU,
# lattice sphere 1M: mean 0.17h, against 0.12h at 3h; random 1M:
# 14h and 12k pieces, against 2.1h and 1.3k pieces).
SPLASHSURF_SETTINGS = {"lattice": (2.0, 1.0), "random": (3.0, 1.0)}
NEWTON_SETTINGS = {"newton": (1.0, 3.0), "newton-aniso": (0.5, 3.0)}


@dataclass(frozen=True)
class PeerResult:
    """One peer reconstruction.

    name: peer name ("splashsurf", "newton", "newton-aniso"); settings: human-readable settings;
    device: where it ran ("cpu x2", "cuda:0"); seconds: median wall time of the timed calls;
    vertices: (m, 3) float32 m; faces: (k, 3) int64 indices into vertices.
    """

    name: str
    settings: str
    device: str
    seconds: float
    vertices: np.ndarray
    faces: np.ndarray


def _median_time(call: Callable[[], object], repeats: int) -> tuple[float, object]:
    """One untimed warm-up call, then (median seconds of `repeats` calls, last call's result)."""
    if repeats < 1:
        raise ValueError(f"repeats={repeats}: need at least one timed call")
    call()
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = call()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def _import_splashsurf():
    try:
        import pysplashsurf  # optional: pysplashsurf
    except ImportError as exc:
        raise ImportError(f"the splashsurf peer needs pysplashsurf: {SPLASHSURF_PIP}") from exc
    return pysplashsurf


_rayon_threads: int | None = None  # splashsurf's thread count, fixed by its first call in this process


def _splashsurf_threads(threads: int | None) -> str:
    """Size splashsurf's thread pool; returns the device text ("cpu x2").

    rayon sizes its global pool once per process, at first use, from RAYON_NUM_THREADS
    (default: all available cores). Its `multi_threading=False` flag is not a substitute:
    measured, it still keeps ~1.7 of 2 cores busy. So a count is set through the variable
    before the first call, and a later call that asks for another count is refused.
    """
    global _rayon_threads
    env = os.environ.get("RAYON_NUM_THREADS")
    fixed = _rayon_threads or (int(env) if env else None)
    if threads is not None and fixed is not None and fixed != threads:
        raise ValueError(
            f"splashsurf threads={threads}: its thread pool already has {fixed} threads "
            f"(RAYON_NUM_THREADS / an earlier call); set RAYON_NUM_THREADS={threads} "
            "before starting Python"
        )
    if threads is not None and fixed is None:
        os.environ["RAYON_NUM_THREADS"] = str(threads)
        fixed = threads
    _rayon_threads = fixed or usable_cores()
    return f"cpu x{_rayon_threads}"


def run_splashsurf(
    x: np.ndarray,
    h: float,
    *,
    kernel: float = 2.0,
    cube: float = 1.0,
    threshold: float = 0.6,
    threads: int | None = None,
    repeats: int = 3,
) -> PeerResult:
    """splashsurf on `x` with particle radius r = PEER_RADIUS_PER_SPACING * h.

    x: (n, 3) float positions m; h: particle spacing m.
    kernel: SPH smoothing length in multiples of r (splashsurf's `smoothing_length`; its
      kernel's compact support is twice that); cube: marching-cubes voxel edge in multiples
      of r (`cube_size`).
      pysplashsurf 0.14.1's docstring says these are absolute lengths, but it multiplies them
      by the particle radius: absolute values give one tiny blob per particle.
    threshold: iso value of the colour field (splashsurf's default 0.6).
    threads: CPU threads (None: all cores; see `_splashsurf_threads`).
    Timed: reconstruct_surface (includes copying x into Rust); not timed: mesh to numpy.
    """
    device = _splashsurf_threads(threads)
    call = splashsurf_call(x, h, kernel=kernel, cube=cube, threshold=threshold)
    seconds, rec = _median_time(call, repeats)
    mesh = rec.mesh
    vertices = np.asarray(mesh.vertices, dtype=np.float32).reshape(-1, 3)
    faces = np.asarray(mesh.triangles, dtype=np.int64).reshape(-1, 3)
    settings = f"smoothing {kernel:g}r cube {cube:g}r iso {threshold:g}"
    return PeerResult("splashsurf", settings, device, seconds, vertices, faces)


def splashsurf_call(x: np.ndarray, h: float, *, kernel: float, cube: float, threshold: float = 0.6):
    """A call of splashsurf's reconstruction on `x` (run_splashsurf's settings; its thread pool as
    sized by RAYON_NUM_THREADS or the first call); returns its reconstruction."""
    ss = _import_splashsurf()
    pts = np.ascontiguousarray(x, dtype=np.float32)
    r = PEER_RADIUS_PER_SPACING * h

    def call():
        return ss.reconstruct_surface(
            pts,
            particle_radius=r,
            rest_density=1000.0,
            smoothing_length=kernel,
            cube_size=cube,
            iso_surface_threshold=threshold,
        )

    return call


def _import_newton():
    try:
        from newton.geometry import ParticleSurface  # optional: newton
    except ImportError as exc:
        raise ImportError(f"the Newton peer needs newton and warp-lang: {NEWTON_PIP}") from exc
    return wp, ParticleSurface


def run_newton(
    x: np.ndarray,
    h: float,
    *,
    anisotropic: bool,
    voxel: float,
    device: str | None = "cuda",
    kernel_radius: float | None = None,
    threshold: float = 0.25,
    repeats: int = 3,
) -> PeerResult:
    """Newton's ParticleSurface on `x` with particle radius r = PEER_RADIUS_PER_SPACING * h.

    x: (n, 3) float positions m; h: particle spacing m.
    voxel: voxel edge in multiples of h. kernel_radius: neighbour-search radius in multiples
      of h; None keeps Newton's default, 3 voxels (its kernel's smoothing length is half of
      it, the cubic B-spline's support all of it).
    anisotropic: Yu & Turk WPCA ellipsoids (needs 25 neighbours inside kernel_radius, else a
      particle keeps the isotropic kernel). threshold: density iso value (Newton's 0.25; the
      field is ~1 inside, since each particle splats volume (2 r)^3 = h^3).
    device: Warp device; None -> Warp's default.
    Timed: extract (exact-size buffers, so it syncs for counts) + wp.synchronize_device.
    Not timed: uploading x (done first, as our surfacer gets particles already on the device)
    and downloading the mesh.
    """
    wp, ParticleSurface = _import_newton()
    wp.init()
    try:
        dev = wp.get_device(device)
    except RuntimeError as exc:  # "cuda" on a machine without a CUDA driver
        raise RuntimeError(f"Newton peer: Warp cannot use device {device!r} here ({exc}); try --device cpu") from exc
    pos = wp.array(np.ascontiguousarray(x, dtype=np.float32), dtype=wp.vec3, device=dev)
    radii = wp.full(pos.shape[0], PEER_RADIUS_PER_SPACING * h, dtype=wp.float32, device=dev)
    surf = ParticleSurface(
        voxel * h,
        anisotropic=anisotropic,
        threshold=threshold,
        device=dev,
        kernel_radius=None if kernel_radius is None else kernel_radius * h,
    )

    def call():
        mesh = surf.extract(pos, radii, compute_normals=True)  # ours returns normals too
        wp.synchronize_device(dev)
        return mesh

    seconds, mesh = _median_time(call, repeats)
    verts, indices, _ = mesh.to_arrays()  # exact-length views of the device buffers
    vertices = np.zeros((0, 3), np.float32) if verts is None else verts.numpy().reshape(-1, 3)
    faces = np.zeros((0, 3), np.int64) if indices is None else indices.numpy().astype(np.int64).reshape(-1, 3)
    kr = 3.0 * voxel if kernel_radius is None else kernel_radius
    settings = f"voxel {voxel:g}h kernel_radius {kr:g}h iso {threshold:g}" + (" aniso" if anisotropic else "")
    return PeerResult("newton-aniso" if anisotropic else "newton", settings, str(dev), seconds, vertices, faces)


def peer_missing(name: str) -> str | None:
    """Why peer `name` cannot run here (the pip command), or None when its package imports."""
    if name not in PEERS:
        raise ValueError(f"peer {name!r}: use one of {', '.join(PEERS)}")
    try:
        (_import_splashsurf if name == "splashsurf" else _import_newton)()
    except ImportError as exc:
        return str(exc)
    return None


def run_peer(
    name: str, x: np.ndarray, h: float, sampling: str, *, device: str | None = None, repeats: int = 3
) -> PeerResult:
    """Peer `name` with the settings the bench uses for `sampling` ("lattice" or "random").

    splashsurf runs on the CPU whatever `device`; Newton on `device`.
    """
    if name == "splashsurf":
        kernel, cube = SPLASHSURF_SETTINGS[sampling]
        return run_splashsurf(x, h, kernel=kernel, cube=cube, repeats=repeats)
    if name in NEWTON_SETTINGS:
        voxel, kernel_radius = NEWTON_SETTINGS[name]
        return run_newton(
            x,
            h,
            anisotropic=name == "newton-aniso",
            voxel=voxel,
            kernel_radius=kernel_radius,
            device=device,
            repeats=repeats,
        )
    raise ValueError(f"peer {name!r}: use one of {', '.join(PEERS)}")
