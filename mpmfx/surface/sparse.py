"""Sparse (block) surfacer: the work follows the surface, not the bounding-box volume.

The passes, in order (each a module; those that run differently on a CPU and a GPU hold both
variants, chosen once per call by :func:`mpmfx.surface.variants.variant`):

1. binning: particles are binned into blocks of 8^3 voxels and gather cells;
2. classify: a block is OUTSIDE (no particle within SparseGrid.reach_vox: the kernel's reach
   and what is read around the surface), INSIDE (it and its neighbours are dense: the surface
   is farther than the kernel and the smoothing reach, grid.dense_rule), or ACTIVE. Voids (OUTSIDE
   blocks the grid boundary does not reach) become ACTIVE next to other blocks and INSIDE within,
   until the voxels' topology tells a bubble (filled) from open space between sparse particles;
3. field: Zhu-Bridson phi at each voxel of ACTIVE blocks, GATHERED from the particles of the
   cells within the kernel support (no atomics), its normal from the blurred weights, and the
   edges that bound the smoothing;
4. flood: outside voxels not connected to an OUTSIDE block are bubbles (-> inside); inside
   voxels not connected to a particle or an INSIDE block are specks of the noisy field (->
   outside);
5. components: inside components holding too few particles become outside;
6. redistance: dilate, renormalise to a distance over the band;
7. close: the closing of the inside (SurfaceParams.close_voids);
8. smooth: mean-curvature flow along the surface;
9. sharpen: convex edges and corners made sharp again (SurfaceParams.sharp_edges); then voxels
   next to a tile take the tile's sign, the topology passes run again, and the level set is
   renormalised to world units;
10. mesh: marching cubes over active cells, normals and velocities;
11. output: the host copies (:meth:`DeviceSurface.download`).

Everything runs on the Warp device (`surface_on_device`, a few host syncs for sizes); the host
copy (`DeviceSurface.download`) is separate, so a caller or the benchmark can leave it out;
`SurfaceResult.stats` / `DeviceSurface.stats` say how long each stage took.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from mpmfx.surface.binning import grid_positions, particle_bounds, sorted_positions
from mpmfx.surface.classify import classify, open_voids
from mpmfx.surface.close import close_voids
from mpmfx.surface.components import remove_small
from mpmfx.surface.cpu_memory import keep_freed_memory
from mpmfx.surface.field import field
from mpmfx.surface.flood import fix_topology
from mpmfx.surface.grid import SparseGrid
from mpmfx.surface.output import dense_output, output_kinds
from mpmfx.surface.params import (
    PARTICLE_RADIUS_PER_SPACING,
    GridTooLarge,
    SparseLevelSet,
    SurfaceParams,
    SurfaceResult,
)
from mpmfx.surface.redistance import add_scalar
from mpmfx.surface.sharpen import sharpen
from mpmfx.surface.variants import Variant, variant

log = logging.getLogger(__name__)

PINNED_DOWNLOAD = True  # DeviceSurface.download's default: page-locked buffers kept between calls (pinned.PINNED)
MAX_ACTIVE_BLOCKS = ((1 << 31) - 1) // (
    3 * 512
)  # the marching cubes' arrays hold 3 edges a voxel, indexed by int32 (Warp's array limit)
SEED_DEPTH = 0.5  # x particle radius: how deep a particle's voxel must be to seed a genuine inside component
SEED_DEPTH_SMOOTHED = 0.25  # voxels, the same after smoothing (a lone particle's blob is ~1 voxel deep then)
SMOOTH_LIMIT = 0.5  # x particle radius: how far smoothing may move the level set inward (smooth.smooth_by_voxel)


@dataclass
class DeviceSurface:
    """The sparse surfacer's result, still on the Warp device (what the benchmark times).

    Active blocks: bcoord (m,) vec3i block coordinates, bmap (block grid) -> active index or
    tile code, values (m * 512,) float32 world-unit level set, vel (m * 512,) vec3 or None,
    w (m * 512,) kernel weight sums, counts (block grid) particles per block. Mesh: world (v,)
    vec3 positions, normals, velocities, faces (3 k,) int32 (device arrays of exact size), or
    None for an empty surface. kind (m,) int32: 0 all-outside, 1 all-inside, 2 holds the band
    (output.classify_output_blocks). stats: cumulative seconds after each stage, active blocks and
    flood-fill rounds (see SurfaceResult.stats)."""

    grid: SparseGrid
    n: int
    bcoord: object
    bmap: object
    counts: object
    values: object
    w: object
    vel: object
    kind: object
    mesh: tuple | None
    stats: dict

    def download(self, params: SurfaceParams, *, pinned: bool | None = None) -> SurfaceResult:
        """Copy to the host: mesh, sparse leaves (with fog density if params.density) and
        (params.dense_output) dense arrays. pinned (None: PINNED_DOWNLOAD): copy the mesh and
        leaves into page-locked buffers kept between calls (pinned.PINNED; CUDA only).
        Adds the seconds of each part to stats ("download_mesh", "download_leaves", "download_dense")."""
        passes = variant(self.values.device)
        pinned = PINNED_DOWNLOAD if pinned is None else pinned
        stats = dict(self.stats)
        t0 = time.perf_counter()
        mesh = passes.download_mesh(self.mesh, with_v=self.vel is not None, pinned=pinned, half=params.half_attributes)
        t1 = time.perf_counter()
        sparse = passes.leaves(self, params, pinned=pinned) if params.leaves else self.no_leaves(params)
        t2 = time.perf_counter()
        result = dense_output(self, params)
        t3 = time.perf_counter()
        stats.update(
            download_mesh=round(t1 - t0, 4), download_leaves=round(t2 - t1, 4), download_dense=round(t3 - t2, 4)
        )
        result.mesh, result.sparse, result.stats = mesh, sparse, stats
        return result

    def no_leaves(self, params: SurfaceParams) -> SparseLevelSet:
        """The sparse level set without a block (params.leaves off): its voxel and background."""
        empty = np.zeros((0, 8, 8, 8), np.float32)
        return SparseLevelSet(
            np.zeros((0, 3), np.int64),
            empty,
            np.zeros((0, 8, 8, 8, 3), np.float32) if self.vel is not None else None,
            np.zeros((0, 3), np.int64),
            self.grid.voxel,
            self.grid.background,
            empty.copy() if params.density else None,
        )


def surface_sparse(x, v, params: SurfaceParams) -> SurfaceResult:
    """The sparse surfacer on host or device particles (inputs already checked:
    mpmfx.surface.reconstruct.surface_particles).

    x: (n, 3) float32 numpy positions (m) or a wp.array of wp.vec3 on the current device;
    v: the same for velocities (m/s), or None."""
    if not isinstance(x, wp.array):
        x = wp.array(np.ascontiguousarray(x, dtype=np.float32), dtype=wp.vec3)
    if v is not None and not isinstance(v, wp.array):
        v = wp.array(np.ascontiguousarray(v, dtype=np.float32), dtype=wp.vec3)
    t0 = time.perf_counter()
    dev = surface_on_device(x, v, params)
    dev.stats["device"] = _lap(t0)
    result = dev.download(params)
    result.stats["download"] = round(time.perf_counter() - t0 - dev.stats["device"], 4)
    return result


def surface_on_device(x, v, params: SurfaceParams) -> DeviceSurface:
    """Level set and mesh of particles x (wp.array of vec3, m) with velocities v (or None),
    left on the device. A handful of host syncs read sizes (active blocks, vertices, faces,
    flood-fill rounds); everything else stays on the GPU."""
    if x.device.is_cpu:  # the call's arrays reuse the previous call's pages (no page faults)
        keep_freed_memory()
    passes = variant(x.device)
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    grid = SparseGrid(*particle_bounds(x), params)
    n = x.shape[0]
    g = grid_positions(x, grid)
    counts, cells, starts, order = passes.bin_particles(g, grid)
    gs = sorted_positions(g, order)
    bmap, bcoord, voids = classify(passes.near_blocks, gs, counts, cells, starts, grid)
    nact = bcoord.shape[0]
    if nact > MAX_ACTIVE_BLOCKS:  # (a 10M-particle sheet one spacing thick at voxel h / 2: 2.6M blocks)
        raise GridTooLarge(
            f"these {n} particles need {nact} active blocks of 8^3 voxels, more "
            f"than one surfacing call can index ({MAX_ACTIVE_BLOCKS}); raise voxel_size (now {grid.voxel:g} m) "
            f"or surface the particles in parts"
        )
    timings["blocks"] = _lap(t0)
    phi, w, vel, edges = field(passes, bcoord, bmap, cells, starts, order, gs, v, grid, params)
    timings["field"] = _lap(t0)
    mark = passes.mark_particles(bcoord, bmap, cells, starts, gs)
    tiles = (grid.far_vox, -grid.r_vox)  # (outside, inside) tile values of the raw field
    steps = fix_topology(passes.flood, bcoord, bmap, phi, mark, tiles, seed_depth=SEED_DEPTH * grid.r_vox)
    if voids is not None:
        open_voids(bmap, phi, voids)
    timings["topology"] = _lap(t0)
    values, steps = _level_set(passes, bcoord, bmap, phi, mark, gs, edges, grid, params, steps)
    timings["smooth"] = _lap(t0)
    with_v = v is not None
    mesh = passes.mesh(bcoord, bmap, values, (grid.background, -grid.background), vel if with_v else None, w, grid)
    timings["mesh"] = _lap(t0)
    kind = output_kinds(values, grid.background, nact)
    log.debug("surface_sparse n=%d blocks=%s active=%d timings=%s", n, grid.nblocks, nact, timings)
    stats = {**timings, "active_blocks": nact, "fill_rounds": steps}
    return DeviceSurface(grid, n, bcoord, bmap, counts, values, w, vel if with_v else None, kind, mesh, stats)


def _level_set(
    passes: Variant, bcoord, bmap, phi, mark, gs, edges, grid: SparseGrid, params: SurfaceParams, steps: int
) -> tuple:
    """From the raw field phi (voxels, topology fixed) to the world-unit level set: dilated,
    redistanced, closed, smoothed, sharpened, tile signs matched, topology fixed again, small
    components removed and renormalised. (values, the flood-fill rounds so far)."""
    nvox = phi.shape[0]
    tiles = (grid.far_vox, -grid.r_vox)
    if params.dilate != 0.0 and nvox:
        wp.launch(add_scalar, nvox, inputs=[phi, -params.dilate / grid.voxel])
        tiles = (tiles[0] - params.dilate / grid.voxel, tiles[1])
    dist = passes.distance(bcoord, bmap, phi, tiles, grid.wide, grid.read_vox)
    tiles = (grid.wide, -grid.wide)
    if params.close_voids > 0.0 and params.smooth_iters > 0 and nvox:
        dist = close_voids(passes.redistance, bcoord, bmap, dist, params.close_voids / grid.voxel, grid.wide)
    # the smoothing reads an INSIDE tile as deep as the dense rule guarantees, not -wide: from a
    # face, its stencil reaches a tile's first rows, which lie about that deep (-wide would pull
    # flat faces outward)
    flow_tiles = (tiles[0], -min(grid.inside_depth, grid.wide))
    phi = passes.smooth(
        bcoord, bmap, dist, params.smooth_iters, flow_tiles, limit=SMOOTH_LIMIT * grid.r_vox, edges=edges
    )
    if params.sharp_edges and edges is not None:  # the faces' planes back at convex edges and corners
        spacing = params.particle_radius / PARTICLE_RADIUS_PER_SPACING / grid.voxel
        sharpen(bcoord, bmap, phi, flow_tiles, edges[0], edges[2], spacing)
    # marching cubes needs no crossing on a tile face; giving voxels next to a tile its sign can
    # seal an outside pocket whose only way out ran along an inside tile (a bubble, seen on
    # random samples), so it comes before the last topology pass, not after. That pass also
    # catches what smoothing did: closed thin outside tunnels (bubbles), cut inside necks (specks).
    passes.match_tiles(bcoord, bmap, phi, nvox)
    seed = SEED_DEPTH_SMOOTHED if params.smooth_iters > 0 else SEED_DEPTH * grid.r_vox
    steps += fix_topology(passes.flood, bcoord, bmap, phi, mark, tiles, seed_depth=seed)
    if params.min_feature_particles > 0 and nvox:
        remove_small(passes.small_labels, bcoord, bmap, phi, gs, mark, params.min_feature_particles, tiles)
    values = wp.empty_like(phi)  # renormalising keeps every sign: the topology stands
    # a voxel the band's width or more from the zero level takes the band's value: phi is a
    # distance there already, but where the Eikonal sweeps stopped short of wide (on a slanted
    # face they converge only what is read: redistance.sweep_count) it steps up to +-wide, and
    # phi / |grad phi| across that step would read as near. An INSIDE tile reads as deep as the
    # smoothing read it (flow_tiles), not -wide, which next to a voxel 3 deep would read as steep too
    passes.renormalise(
        bcoord, bmap, phi, flow_tiles, grid.voxel, grid.background, values, far=float(params.band_voxels)
    )
    return values, steps


def _lap(t0: float) -> float:
    wp.synchronize()
    return round(time.perf_counter() - t0, 4)
