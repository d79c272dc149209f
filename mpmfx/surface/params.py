"""Parameter and result types of the surfacer (numpy only; no Warp import here)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

PARTICLE_RADIUS_PER_SPACING = 0.6
"""Particle radius r of the surfacer in units of the particle spacing h, as the surface stage,
the benchmark and the peers use it (one place). 0.6 h rather than half the spacing: with
kernel_radius 3.7 it keeps thin one-layer parts closed (docs/benchmarks.md's surfacing
figures are taken at this radius)."""


def kernel_volume(radius: float) -> float:
    """Integral of the Zhu-Bridson kernel (1 - s^2)^3 over its ball of `radius` (radius^3 units):
    a kernel weight sum divided by it is a number density."""
    return 4.0 * math.pi * radius**3 * 16.0 / 315.0


class GridTooLarge(ValueError):
    """The particles need a grid one surfacing call cannot hold at this voxel_size; `detail` says
    how much and what to do (the message is "SurfaceParams.voxel_size: " + detail)."""

    def __init__(self, detail: str):
        super().__init__(f"SurfaceParams.voxel_size: {detail}")
        self.detail = detail


@dataclass(frozen=True)
class SurfaceParams:
    """Settings of :func:`mpmfx.surface.surface_particles`. Lengths are world units (m).

    particle_radius: radius r of one particle; the pipeline passes PARTICLE_RADIUS_PER_SPACING
        (0.6) x the particle spacing.
    radius_scale: artist multiplier on r (grows / shrinks the surface; the kernel support stays).
    voxel_size: level-set voxel edge; None -> 0.5 * particle_radius (independent of the sim dx).
        voxel_size = particle_radius with smooth_iters = 4 is the benchmark's "fast".
        The default, 2, keeps a lone particle's drop at 0.68 r (unsmoothed 1.0 r) wherever it sits;
        at 3 or 4 steps it survives only near a voxel corner (3 of 20 random places; 0.47 r there),
        and at voxel_size = r not even at 1 step: spray of single particles goes.
    smooth_iters: steps of the level set's mean-curvature flow (mpmfx.surface.smooth: each spreads the
        surface's noise along it as a [1 2 1]/4 blur pass would, without eroding a thin sheet),
        after it is made a signed distance over the band; together they move the surface at most
        0.5 particle_radius inward (so a drop or a filament is not shrunk away), and an edge no
        further than twice the noise of its samples (a lattice's edges stay sharp, random
        samples' are smoothed: mpmfx.surface.edges). The surface stage runs 8 at
        voxel_size = r / 2; more steps shrink small curved bodies (a 20k random sphere loses
        1.3 % of its volume at 8, 1.9 % at 12).
    dilate: offset of the surface before smoothing, outward (+) or inward (-).
    close_voids: radius of a ball rolled over the outside of the surface before smoothing (m;
        0 = off): the dents it cannot enter fill (a morphological closing), as the voids of
        random samples do, without rounding convex edges. About one particle spacing
        (particle_radius / 0.6) works best on random samples. Only fills deeper than 0.06 of
        the radius are kept (close.CLOSE_GATE): on the grid the closing shifts a flat face a little, and a
        lattice's faces stay where they were.
    min_feature_particles: connected blobs holding fewer particles than this are removed.
    band_voxels: narrow-band half width in voxels; the level set is clipped to +-band*voxel.
    kernel_radius: Zhu-Bridson kernel support R in units of particle_radius. With the
        (1 - s^2)^3 kernel the weighted centroid of a half-space ball sits 0.246 R deep, so
        R = 4.06 r puts the zero level on a flat boundary of a continuum; on discrete layers
        3.7 fits best (box faces within 0.02 h, sphere volume +0.3 %, r = 0.5 h); at
        r = 0.6 h, 4.2 and 4.6 shrink random samples by 2-4 % volume.
    normal_radius: the normal that xbar is projected on comes from a kernel this many times
        wider than kernel_radius (the weight field blurred to that width; 1 = the kernel's own
        gradient). On random samples the kernel's own normal and xbar share their errors and the
        surface sits ~0.1 h inside (-2 % volume); 3 leaves -0.6 % and lattices unchanged (30k
        particles, r = 0.6 h).
    anisotropic: Yu & Turk (2013) anisotropic kernels: each particle's kernel is stretched
        along the principal axes of its neighbours (long along a sheet or surface, short across
        it), so one-particle-thick sheets of water stay sheets instead of beading into holes.
        Particles with fewer than ANISO_MIN_NEIGHBOURS neighbours (spray) stay round. Costs a
        particle pass and a wider gather.
    sharp_edges: give convex edges and corners back the sharpness a random sample loses
        there (mpmfx.surface.sharpen: where the edge gate is open, the field takes the intersection of
        the faces' planes, fitted where the surface is flat a few spacings away; outward only,
        at most 1.5 spacings; not where the body is thinner than 2.5 spacings; each cell as far
        as the decisions of the cells around it agree). Shots turn it on for every surface group
        without a fluid in it (config.Surface.sharp_edges = "auto"); off here, as the smallest
        call. Round bodies and sheets come out as they are without it (a tube 5 spacings
        across, blobs of 300 particles: not a vertex moves; random spheres and tori: at most
        0.07 % of the vertices, by at most 0.01 h). A moving body's vertices jitter a little
        more, its rendered pictures no more (mpmfx.bench.surface_flicker). On a 100k random box
        the vertices' mean error drops by about a tenth and the largest by about a third.
    dense_output: also return the level set (and velocity, density) as dense
        arrays over the band's bounding box; False returns only `SurfaceResult.sparse` (the
        dense arrays are then empty) -- what to use at millions of particles.
    density: also return `SparseLevelSet.density`, a fog density (0..1,
        dimensionless: kernel weight sum over its bulk value) on the stored leaves, for granular /
        volume looks; False (the default) costs nothing.
    leaves: return the sparse level set's leaves (`SurfaceResult.sparse`); False returns the
        mesh alone (the leaves then hold no block): at 10M particles the leaves and their
        velocities are ~1 GB to copy off a GPU, wasted where nothing reads them.
    half_attributes: return the mesh's normals and velocities as float16 (what a frame file
        stores), converted on the device: numpy's conversion of a 3M-vertex mesh's takes ~0.4 s
        of host time, the device's a millisecond, and half the bytes cross to the host.
    """

    particle_radius: float
    radius_scale: float = 1.0
    voxel_size: float | None = None
    smooth_iters: int = 2
    dilate: float = 0.0
    close_voids: float = 0.0
    min_feature_particles: int = 0
    band_voxels: int = 3
    kernel_radius: float = 3.7
    normal_radius: float = 3.0
    anisotropic: bool = False
    sharp_edges: bool = False
    dense_output: bool = True
    density: bool = False
    leaves: bool = True
    half_attributes: bool = False

    def __post_init__(self) -> None:
        def bad(field: str, fix: str) -> ValueError:
            return ValueError(f"SurfaceParams.{field}: {fix}")

        if not (math.isfinite(self.particle_radius) and self.particle_radius > 0):
            raise bad("particle_radius", f"got {self.particle_radius!r}; give a positive length in metres")
        if not (math.isfinite(self.radius_scale) and self.radius_scale > 0):
            raise bad("radius_scale", f"got {self.radius_scale!r}; give a positive multiplier (1.0 = as is)")
        if self.voxel_size is not None and not (math.isfinite(self.voxel_size) and self.voxel_size > 0):
            raise bad("voxel_size", f"got {self.voxel_size!r}; give a positive length or None")
        if self.smooth_iters < 0:
            raise bad("smooth_iters", f"got {self.smooth_iters}; give 0 or more passes")
        if not math.isfinite(self.dilate):
            raise bad("dilate", f"got {self.dilate!r}; give a finite length")
        if not (math.isfinite(self.close_voids) and self.close_voids >= 0.0):
            raise bad(
                "close_voids", f"got {self.close_voids!r}; give 0 (off) or a radius in metres, ~ the particle spacing"
            )
        if self.min_feature_particles < 0:
            raise bad("min_feature_particles", f"got {self.min_feature_particles}; give 0 (off) or more")
        if self.band_voxels < 1:
            raise bad("band_voxels", f"got {self.band_voxels}; give at least 1 voxel")
        if not (math.isfinite(self.kernel_radius) and self.kernel_radius >= 1.0):
            raise bad("kernel_radius", f"got {self.kernel_radius!r}; give >= 1 (x particle_radius), 3.7 by default")
        if not isinstance(self.anisotropic, bool):
            raise bad("anisotropic", f"got {self.anisotropic!r}; give True or False")
        if not isinstance(self.sharp_edges, bool):
            raise bad("sharp_edges", f"got {self.sharp_edges!r}; give True or False")
        if self.sharp_edges and self.smooth_iters == 0:
            raise bad(
                "sharp_edges",
                "needs smooth_iters > 0 (the edges are found while smoothing); "
                "give smooth_iters or turn sharp_edges off",
            )
        for flag in ("density", "leaves", "half_attributes"):
            if not isinstance(getattr(self, flag), bool):
                raise bad(flag, f"got {getattr(self, flag)!r}; give True or False")

    @property
    def resolved_voxel_size(self) -> float:
        """Voxel edge in world units (m)."""
        return float(self.voxel_size) if self.voxel_size is not None else 0.5 * self.particle_radius


@dataclass
class LevelSet:
    """Narrow-band signed distance on a voxel grid aligned to multiples of voxel_size.

    values: (a, b, c) float32, world units, negative inside, clipped to +-background.
    ijk0: (3,) int64; values[i, j, k] sits at world ((ijk0 + (i, j, k)) * voxel_size), so the
        index space equals an OpenVDB transform of uniform scale voxel_size.
    """

    values: np.ndarray
    ijk0: np.ndarray
    voxel_size: float
    background: float

    @property
    def origin(self) -> np.ndarray:
        """(3,) float64 world position of values[0, 0, 0]."""
        return self.ijk0.astype(np.float64) * self.voxel_size


@dataclass
class SurfaceMesh:
    """Triangle mesh of the zero level, outward-facing (counter-clockwise seen from outside).

    vertices: (m, 3) float32 world; faces: (k, 3) int32; normals: (m, 3) float32 unit, outward;
    velocities: (m, 3) float32 world/s (zeros when no velocities were given); normals and
    velocities float16 with SurfaceParams.half_attributes.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    velocities: np.ndarray

    @classmethod
    def empty(cls) -> SurfaceMesh:
        z = np.zeros((0, 3), np.float32)
        return cls(z, np.zeros((0, 3), np.int32), z.copy(), z.copy())


@dataclass
class SparseLevelSet:
    """The level set as OpenVDB-style leaves: blocks of 8^3 voxels near the surface.

    block_ijk: (m, 3) int64 index of each block's first voxel (multiples of 8; voxel index space
        as LevelSet.ijk0, world = index * voxel_size); values: (m, 8, 8, 8) float32 world units,
        clipped to +-background; velocity: (m, 8, 8, 8, 3) float32 m/s or None; inside_ijk: (k, 3)
        int64 first voxels of blocks wholly inside (value -background); every other voxel is
        outside (+background).
    density: (m, 8, 8, 8) float32 fog density in [0, 1] (dimensionless: the kernel weight sum
        over its value in the bulk of the material, clamped), 1 on the inside blocks and 0
        elsewhere; or None (SurfaceParams.density off). The leaves may be stored as float16.
    """

    block_ijk: np.ndarray
    values: np.ndarray
    velocity: np.ndarray | None
    inside_ijk: np.ndarray
    voxel_size: float
    background: float
    density: np.ndarray | None = None

    def to_dense(self, *, ijk0: np.ndarray | None = None, shape: tuple[int, int, int] | None = None) -> LevelSet:
        """The same level set as a dense LevelSet: over voxels ijk0 .. ijk0 + shape - 1, by default
        the bounding box of the stored blocks."""
        if ijk0 is None or shape is None:
            if len(self.block_ijk) == 0:
                return LevelSet(
                    np.zeros((0, 0, 0), np.float32), np.zeros(3, np.int64), self.voxel_size, self.background
                )
            ijk0 = self.block_ijk.min(axis=0)
            shape = tuple(int(s) for s in self.block_ijk.max(axis=0) - ijk0 + 8)
        ijk0 = np.asarray(ijk0, np.int64)
        values = self._paste(self.values, ijk0, shape, outside=self.background, inside=-self.background)
        return LevelSet(values, ijk0, self.voxel_size, self.background)

    def velocity_dense(self, ijk0: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray | None:
        """(a, b, c, 3) float32 velocity (m/s) over the same voxels as `to_dense` (0 outside stored blocks)."""
        if self.velocity is None:
            return None
        return self._paste(self.velocity, ijk0, shape, outside=0.0, inside=None)

    def density_dense(self, ijk0: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray | None:
        """(a, b, c) float32 fog density (0..1) over the same voxels as `to_dense`: 1 on inside
        blocks, 0 outside the stored ones; None when there is no density."""
        if self.density is None:
            return None
        return self._paste(self.density, ijk0, shape, outside=0.0, inside=1.0)

    def _paste(self, blocks: np.ndarray, ijk0, shape, *, outside: float, inside: float | None) -> np.ndarray:
        """float32 array of `shape` (+ the blocks' trailing axes) holding `outside`, the inside
        blocks at `inside` (None: left at `outside`) and the stored `blocks` (m, 8, 8, 8, ...)
        over them, each clipped to the window that starts at voxel ijk0."""
        shape = tuple(int(s) for s in shape)
        out = np.full(shape + blocks.shape[4:], outside, np.float32)  # blocks may be stored as float16
        ijk0 = np.asarray(ijk0, np.int64)

        def paste(corner: np.ndarray, block) -> None:
            lo = corner - ijk0
            a, b = np.maximum(lo, 0), np.minimum(lo + 8, shape)
            if np.all(b > a):
                src = block if np.isscalar(block) else block[tuple(slice(x - y, z - y) for x, y, z in zip(a, lo, b))]
                out[tuple(slice(x, z) for x, z in zip(a, b))] = src

        if inside is not None:
            for corner in self.inside_ijk:
                paste(corner, inside)
        for corner, block in zip(self.block_ijk, blocks):
            paste(corner, block)
        return out


@dataclass
class SurfaceResult:
    """Output of :func:`surface_particles`.

    velocity: (a, b, c, 3) float32 world/s on the level-set grid (kernel-weighted particle
        velocity, 0 where no particle reaches), or None when no velocities were given.
    density: (a, b, c) float32 particles per m^3 (kernel estimate).
    sparse: the level set as 8^3 leaves (what the pipeline stores).
    stats: how the call went, for benchmarks and logs: cumulative seconds after each stage
        ("blocks", "field", "topology", "smooth", "mesh"), "device" (all device work) and
        "download" (the copy to the host), "active_blocks", "fill_rounds" (flood-fill sweeps).
    """

    level_set: LevelSet
    mesh: SurfaceMesh
    velocity: np.ndarray | None
    density: np.ndarray | None
    sparse: SparseLevelSet | None = None
    stats: dict = field(default_factory=dict)
