"""Sparse (block) surfacer: the work follows the surface, not the bounding-box volume.

1. blocks: particles are binned into blocks of 8^3 voxels (count, radix sort by block);
   a block is OUTSIDE (no particle within SparseGrid.reach_vox: the kernel's reach and what
   is read around the surface), INSIDE (it and its neighbours
   are at least half full: the surface is farther than the kernel and the smoothing reach, see
   _dense_rule), or ACTIVE.
   OUTSIDE blocks the grid boundary does not reach (voids) become ACTIVE next to other blocks and
   INSIDE within, until the voxels' topology tells a bubble (filled) from the open space between
   sparse particles (_settle_voids, _open_void_cores).
2. field: Zhu-Bridson phi at each voxel of ACTIVE blocks, GATHERED from the particles of the
   blocks within the kernel support (no atomics);
3. topology: outside voxels not connected to an OUTSIDE block are bubbles (-> inside); inside
   voxels not connected to a particle or an INSIDE block are specks of the noisy field (->
   outside). Flood fill by line sweeps along block rows (8 voxels of progress per launch),
   which settles in a few rounds because the band is thin;
4. dilate, renormalise, smooth (mean-curvature flow), give voxels next to a tile the tile's sign, topology again,
   renormalise to world units;
5. marching cubes over active cells (Warp's tables, copied in :mod:`mpmfx.surface.mc_tables`),
   normals and velocities.

Everything runs on the Warp device (`surface_on_device`, a few host syncs for sizes); the host
copy (`DeviceSurface.download`) is separate, so a caller or the benchmark can leave it out;
`SurfaceResult.stats` / `DeviceSurface.stats` say how long each stage took.
Device times at 10M particles: README, "Benchmarks".
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from mpmfx.surface.cpu_memory import keep_freed_memory
from mpmfx.surface.launch import launch_sequence, launch_split, launch_split_scratch
from mpmfx.surface.params import PARTICLE_RADIUS_PER_SPACING, GridTooLarge, SurfaceParams, SurfaceResult

log = logging.getLogger(__name__)

BS = 8
PINNED_DOWNLOAD = True  # DeviceSurface.download's default: page-locked buffers kept between calls (sparse_output.PINNED); H200, 10M, 'fast', the copy 13-45 -> 8-14 ms
CELLS_PER_BLOCK = 2  # gather cells per block edge (sparse_kernels.CS = BS / 2 voxels)
MAX_BLOCKS = 1 << 26  # block-grid cells: 2^26 blocks = 2^35 voxels of bounding box (8x as many int32 gather cells)
MAX_ACTIVE_BLOCKS = ((1 << 31) - 1) // (3 * 512)  # the marching cubes' arrays hold 3 edges a voxel, indexed by int32 (Warp's array limit)
MAX_SWEEP_ROUNDS = 1024
NORMAL_STEP = 2  # voxels between the taps of the weight blur (the weights are smooth at 1 voxel)
BLUR_MIN_SPLIT = 1024  # blocks below which the weight blur's passes run on one CPU thread (a pass's barrier costs ~20-50 us)
MAX_BLOCK_SWEEP_ROUNDS = 256  # block-grid flood fill (a full line per launch: settles in a few rounds)
SEED_DEPTH = 0.5  # x particle radius: how deep a particle's voxel must be to seed a genuine inside component
SMOOTH_LIMIT = 0.5  # x particle radius: how far smoothing may move the level set inward (see _smooth)
EDGE_CURVATURE = (0.35, 0.5)  # x 1 / the wide normal's blur width: a convex edge starts / is whole (edge_kernels)
EDGE_NOISE = 2.0  # x the samples' noise (standard deviation): how far the smoothing may move an edge inward
EDGE_PIT = 0.25  # 1/voxel: a pit along an edge this sharply curved (or more) stops the flow rounding the edge there (sparse_kernels.edge_flow_step); 0.1 filled more but flickered more (docs/surfacing-log.md, nineteenth step)
SHARP = {  # sparse._sharpen (sharp_kernels); lengths in particle spacings h unless said
    "band": 3.0,  # voxels: cells whose centre lies this near the zero level
    "thin": 2.5,  # and where the body is thicker than this (a sheet is its faces back to back)
    "near": 2.5, "far": 5.5,  # a direction's two points: near out from the cell, then on along the surface to far
    "width": 1.5,  # the points to each side whose normals must agree too
    "cos_flat": math.cos(math.radians(12.0)),  # normals that agree
    "plane_tol": 0.5,  # each point this near the other's tangent plane
    "cos_same": math.cos(math.radians(15.0)),  # planes closer than this are one
    "votes": 3.0,  # directions that must find a plane (of sharp_kernels.DIRECTIONS, 16; at 2, a spot of a 20k random torus passed)
    "support": 0.3,  # voxels: a plane's points this far over another's at most (convex)
    "cos_apart": math.cos(math.radians(65.0)),  # at least two planes this far apart (an edge, not a face)
    "cos_open": math.cos(math.radians(120.0)),  # and none further (faces back to back: a sheet's rim)
    "limit": 1.5,  # the most the field moves outward
    "rounding": 2.0,  # voxels: the crest's radius (0 flickered twice as much on a moving box, 3 gave back a third of the gain)
    # cells on each side whose decisions weigh a cell's sharpening (sharp_kernels.sharpen_weight): at
    # 0 each cell sharpened all or nothing, and where a narrow face's votes hovered about `votes`
    # along an edge it stopped and started in ledges up to 1.3 h high (water_dam's splash frame)
    "spread": 2,
}
EDGE_BAND = 3.0  # voxels from the raw zero level where a 2^3 cell's corner looks for an edge (its voxels within ~2)
FLOW_DT = 0.25  # voxel^2, one smoothing step (sparse_kernels.curvature_flow): a [1 2 1]/4 pass's spread along the surface
FLOW_BAND = 3.0  # voxels: the smoothing moves the values this close to the zero level (fully within FLOW_BAND - 1)
FLOW_REACH = 4  # voxels from the zero level that the smoothing reads: FLOW_BAND and its stencil
ANISO_NORMAL_ITERS = 4  # inverse-power iterations that turn the normal towards the neighbours' thinnest axis
ANISO_COV_EPS = 0.01  # x kernel radius^2: regularises the covariance of a flat (lattice) sheet
ANISO_MAX_RATIO = 4.0  # Yu & Turk's k_r: an ellipsoid's axes differ by at most this factor
ANISO_MAX_STRETCH = 1.6  # longest axis / the isotropic kernel radius (bounds the gather's reach)
ANISO_MIN_NEIGHBOURS = 8  # fewer neighbours within the kernel (spray) keep a round kernel; a one-layer sheet has ~15
LINE_KERNELS_ON_CPU = True  # tests compare both paths on the CPU (tests/surface/test_line_kernels.py)
MAX_DENSE_FILL = 0.5  # of a full block's particles: the most the INSIDE rule asks of a neighbour (_dense_rule)
SEED_DEPTH_SMOOTHED = 0.25  # voxels, the same after smoothing (a lone particle's blob is ~1 voxel deep then)
NO_FAR = 3.0e38  # _renormalise's `far` where every value is renormalised
CLOSE_GATE = (0.06, 0.12)  # x the closing radius: fills the closing drops / keeps in full (_close_voids); it shifts flat lattice faces 0.03-0.05

class SparseGrid:
    """Block grid aligned to multiples of 8 voxels (OpenVDB leaf alignment), with empty margins.

    lo, hi: (3,) world bounds of the particles (m)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, params: SurfaceParams):
        self.voxel = params.resolved_voxel_size
        r = params.particle_radius * params.radius_scale
        self.r_vox = r / self.voxel
        self.kernel_vox = params.kernel_radius * params.particle_radius / self.voxel
        # the gather's reach: the longest axis of a particle's kernel
        self.gather_vox = self.kernel_vox * (ANISO_MAX_STRETCH if params.anisotropic else 1.0)
        # blur passes of the weight field that widen the kernel to normal_radius x: the kernel's
        # variance per axis is 0.0909 R^2, a [1 2 1]/4 pass with taps NORMAL_STEP voxels apart
        # adds 0.5 NORMAL_STEP^2 voxel^2
        added = (params.normal_radius**2 - 1.0) * 0.0909 * self.kernel_vox**2
        self.normal_passes = int(round(added / (0.5 * NORMAL_STEP**2)))
        self.wide_sigma = math.sqrt(0.0909 * self.kernel_vox**2 + self.normal_passes * 0.5 * NORMAL_STEP**2)  # voxels
        self.background = params.band_voxels * self.voxel
        self.far_vox = max(self.kernel_vox, self.r_vox + params.band_voxels + 1.0)
        self.wide = float(params.band_voxels + smooth_reach(params) + 2)
        # voxels from the zero level whose distance is read: by the smoothing's steps, and by the
        # final renormalise's differences across the band (_eikonal_sweeps converges them)
        self.read_vox = float(max(smooth_reach(params), params.band_voxels + 1))
        # the active blocks: those with a voxel within reach_vox of a particle. They must hold
        # what is read around the surface: `read` voxels around the zero level, which the
        # smoothing moves outward by a voxel or so (s = read + 1 from the raw field's inside,
        # phi <= dilation, r' = r + dilation voxels). An inside point x of the Zhu-Bridson field
        # has xbar, the weighted mean of the particles within the gather's reach R, within r'
        # of x, so along any direction u some particle p has (p - x).u >= -r', and x + s u lies
        # within sqrt(R^2 + s^2 + 2 s r') of p: the reach. It covers a surface bridged between
        # sparse particles (spray: the raw inside up to R from them) as well as a body's. The
        # projection on the wide normal bounds only the normal part of x - xbar; measured, no
        # voxel within `read` of the raw inside lies outside the active blocks (spray, the
        # splash frame with and without anisotropy, random boxes; test_sparse), 0-70 within
        # read + 1. It was r' + band + smoothing + 2 (9 voxels at "fine"), a fifth to a quarter
        # more blocks than that (100k lattice torus "fine": 3541 -> 2917 blocks, 10.2 -> 7.5
        # voxels; where the weights' blur loses a little more of its tail, vertices move by p99
        # 5e-4 h on the 30k bench cases, one of the random box's 0.31 h where a corner sharpens
        # otherwise, p99 2.5e-3 h on the splash frame; errors the same to four digits at 100k)
        dilation = max(params.dilate, 0.0) / self.voxel
        s = self.read_vox + 1.0
        self.reach_vox = math.sqrt(self.gather_vox**2 + s * s + 2.0 * s * (self.r_vox + dilation))
        self.reach_blocks = int(math.ceil(self.reach_vox / BS))
        self.dense_reach, self.dense_min, self.inside_depth = _dense_rule(self, params)
        lo = np.floor(np.asarray(lo, np.float64) / self.voxel)
        hi = np.floor(np.asarray(hi, np.float64) / self.voxel)
        margin = self.reach_blocks + 1  # boundary blocks are always OUTSIDE: flood-fill seeds
        blo = np.floor(lo / BS).astype(np.int64) - margin
        bhi = np.floor(hi / BS).astype(np.int64) + margin
        self.nblocks = tuple(int(s) for s in (bhi - blo + 1))
        if math.prod(self.nblocks) > MAX_BLOCKS:
            raise GridTooLarge(
                f"a block grid of {self.nblocks} would cover these particles; "
                f"raise voxel_size (now {self.voxel:g} m) or drop far-flung particles before surfacing"
            )
        self.ijk0 = blo * BS  # voxel index of grid coordinate 0
        self.origin = self.ijk0.astype(np.float64) * self.voxel


def smooth_reach(params: SurfaceParams) -> int:
    """Voxels from the zero level that the smoothing's steps read (0 without smoothing): the
    flow moves only values within FLOW_BAND and reads their neighbours, however many steps."""
    return min(params.smooth_iters, FLOW_REACH)


def _dense_rule(grid: SparseGrid, params: SurfaceParams) -> tuple[int, int, float]:
    """(dense_reach blocks, dense_min particles, depth voxels): a block is INSIDE when every
    block within dense_reach holds at least dense_min particles (sparse_kernels.classify_blocks);
    its voxels then lie at least `depth` voxels under a flat surface.

    An INSIDE block stands for the deep interior: its voxels read constant tile values (raw
    field -r, distance -grid.wide), which is right only where the surface lies at least
    `depth` voxels away: the kernel's reach and the smoothing's (smooth_reach), less one
    voxel (the kernel's outermost voxel weighs little).
    A block cut by a flat face holds the fraction of the particles of a full block (at the
    nominal spacing particle_radius / PARTICLE_RADIUS_PER_SPACING, what the pipeline passes)
    that lies inside the face. So with dense_reach rings of neighbours each holding fill x a
    full block, the surface lies at least (dense_reach - 1 + fill) BS voxels outside an INSIDE
    block (an outer ring could not be dense if an inner one were cut). fill is at most
    MAX_DENSE_FILL: a fuller threshold would catch interior blocks by their count noise.
    The old rule (a quarter of a packing at spacing 2 r: a block ~15 % full) let blocks 1-3
    voxels under a face be INSIDE; the blur read -wide there and pushed patches of the face a
    voxel (0.5 h) outward, wherever the face cut its block so (random box, "fine": 10M 0.147
    -> 0.117 h mean error, 1M 0.137 -> 0.119 h; 2-core CPU, the H100's numbers to the digit)."""
    # the kernel's reach across the surface is the round kernel's (anisotropic kernels are
    # short across it, long only along it)
    depth = max(grid.kernel_vox, float(smooth_reach(params))) - 1.0
    reach = 1 + max(0, int(math.ceil((depth - MAX_DENSE_FILL * BS) / BS)))
    fill = min(max((depth - (reach - 1) * BS) / BS, 1.0 / BS), MAX_DENSE_FILL)
    spacing = params.particle_radius / PARTICLE_RADIUS_PER_SPACING
    full = (BS * grid.voxel / spacing) ** 3
    return reach, max(1, int(math.ceil(fill * full))), (reach - 1 + fill) * BS


@dataclass
class DeviceSurface:
    """The sparse surfacer's result, still on the Warp device (what the benchmark times).

    Active blocks: bcoord (m,) vec3i block coordinates, bmap (block grid) -> active index or
    tile code, values (m * 512,) float32 world-unit level set, vel (m * 512,) vec3 or None,
    w (m * 512,) kernel weight sums, counts (block grid) particles per block. Mesh: world (v,)
    vec3 positions, normals, velocities, faces (3 k,) int32 (device arrays of exact size), or
    None for an empty surface. kind (m,) int32: 0 all-outside, 1 all-inside, 2 holds the band
    (classify_output_blocks). stats: cumulative seconds after each stage, active blocks and
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
        leaves into page-locked buffers kept between calls (sparse_output.PINNED; CUDA only).
        Adds the seconds of each part to stats ("download_mesh", "download_leaves", "download_dense")."""
        import warp as wp
        from mpmfx.surface import sparse_mesh_kernels as M
        from mpmfx.surface import sparse_output as O

        pinned = PINNED_DOWNLOAD if pinned is None else pinned
        stats = dict(self.stats)
        t0 = time.perf_counter()
        mesh = O.download_mesh(wp, M, self.mesh, with_v=self.vel is not None, pinned=pinned)
        t1 = time.perf_counter()
        sparse = O.sparse_output(wp, M, self, params, pinned=pinned)
        t2 = time.perf_counter()
        result = O.dense_output(wp, M, self, params)
        t3 = time.perf_counter()
        stats.update(download_mesh=round(t1 - t0, 4), download_leaves=round(t2 - t1, 4), download_dense=round(t3 - t2, 4))
        result.mesh, result.sparse, result.stats = mesh, sparse, stats
        return result


def surface_sparse(wp, x, v, params: SurfaceParams) -> SurfaceResult:
    """Grid.SPARSE path of :func:`mpmfx.surface.surface_particles` (inputs already checked).

    x: (n, 3) float32 numpy positions (m) or a wp.array of wp.vec3 on the current device;
    v: the same for velocities (m/s), or None."""
    if not isinstance(x, wp.array):
        x = wp.array(np.ascontiguousarray(x, dtype=np.float32), dtype=wp.vec3)
    if v is not None and not isinstance(v, wp.array):
        v = wp.array(np.ascontiguousarray(v, dtype=np.float32), dtype=wp.vec3)
    t0 = time.perf_counter()
    dev = surface_on_device(wp, x, v, params)
    dev.stats["device"] = _lap(wp, t0)
    result = dev.download(params)
    result.stats["download"] = round(time.perf_counter() - t0 - dev.stats["device"], 4)
    return result


def particle_bounds(wp, S, x) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (3,) float64 world bounds of x (wp.array of vec3), computed on the device;
    ValueError when a position is NaN or infinite."""
    out = wp.array(np.array([np.inf] * 3 + [-np.inf] * 3 + [0.0], np.float32), dtype=float)
    threads = min(x.shape[0], 1 << 16)  # each thread reduces a strided slice, then 7 atomics
    wp.launch(S.bounds, threads, inputs=[x, threads, out])
    b = out.numpy().astype(np.float64)
    if b[6] > 0:
        raise ValueError(f"surface_particles: x holds {int(b[6])} NaN or inf positions; fix the simulation frame")
    return b[:3], b[3:6]


def surface_on_device(wp, x, v, params: SurfaceParams) -> DeviceSurface:
    """Level set and mesh of particles x (wp.array of vec3, m) with velocities v (or None),
    left on the device. A handful of host syncs read sizes (active blocks, vertices, faces,
    flood-fill rounds); everything else stays on the GPU."""
    from mpmfx.surface import sparse_kernels as S
    from mpmfx.surface import sparse_mesh_kernels as M
    from mpmfx.surface import topology_kernels as T

    if x.device.is_cpu:  # the call's arrays reuse the previous call's pages (no page faults)
        keep_freed_memory()
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    grid = SparseGrid(*particle_bounds(wp, S, x), params)
    n = x.shape[0]
    # grid coordinates on the device: float32 keeps 1e-4 voxel at 2000 voxels across
    g = wp.empty(n, dtype=wp.vec3)
    wp.launch(S.to_grid, n, inputs=[x, wp.vec3(*grid.origin.astype(np.float32)), 1.0 / grid.voxel, g])
    counts, cells, starts, order = _bin_particles(wp, S, g, grid)
    gs = _sorted_positions(wp, S, g, order)
    bmap, bcoord, voids = _classify(wp, S, gs, counts, cells, starts, grid)
    nact = bcoord.shape[0]
    if nact > MAX_ACTIVE_BLOCKS:  # (a 10M-particle sheet one spacing thick at voxel h / 2: 2.6M blocks)
        raise GridTooLarge(
            f"these {n} particles need {nact} active blocks of 8^3 voxels, more "
            f"than one surfacing call can index ({MAX_ACTIVE_BLOCKS}); raise voxel_size (now {grid.voxel:g} m) "
            f"or surface the particles in parts")
    nvox = nact * BS**3
    timings["blocks"] = _lap(wp, t0)
    with_v = v is not None
    phi, w, vel, edges = _field(wp, S, bcoord, bmap, cells, starts, order, gs, v, grid, params)
    timings["field"] = _lap(wp, t0)
    mark = _mark_particle_voxels(wp, T, bcoord, bmap, cells, starts, gs)
    tiles = (grid.far_vox, -grid.r_vox)  # (outside, inside) tile values of the raw field
    steps = _fix_topology(wp, T, bcoord, bmap, phi, mark, tiles, seed_depth=SEED_DEPTH * grid.r_vox)
    if voids is not None:
        _open_void_cores(wp, S, bmap, phi, voids)
    timings["topology"] = _lap(wp, t0)
    if params.dilate != 0.0 and nvox:
        wp.launch(S.add_scalar, nvox, inputs=[phi, -params.dilate / grid.voxel])
        tiles = (tiles[0] - params.dilate / grid.voxel, tiles[1])
    dist = _distance(wp, S, bcoord, bmap, phi, tiles, grid.wide, grid.read_vox)
    tiles = (grid.wide, -grid.wide)
    if params.close_voids > 0.0 and params.smooth_iters > 0 and nvox:
        dist = _close_voids(wp, S, bcoord, bmap, dist, params.close_voids / grid.voxel, grid.wide)
    # the smoothing reads an INSIDE tile as deep as the dense rule guarantees, not -wide: from a
    # face, its stencil reaches a tile's first rows, which lie about that deep (with the blur it
    # replaced, -wide pulled flat faces +0.006 h out: 100k lattice box "fine" 0.0453 -> 0.0420 h)
    flow_tiles = (tiles[0], -min(grid.inside_depth, grid.wide))
    phi = _smooth(wp, S, bcoord, bmap, dist, params.smooth_iters, flow_tiles, limit=SMOOTH_LIMIT * grid.r_vox, edges=edges)
    if params.sharp_edges and edges is not None:  # the faces' planes back at convex edges and corners
        spacing = params.particle_radius / PARTICLE_RADIUS_PER_SPACING / grid.voxel
        _sharpen(wp, bcoord, bmap, phi, flow_tiles, edges[0], edges[2], spacing)
    # marching cubes needs no crossing on a tile face; giving voxels next to a tile its sign can
    # seal an outside pocket whose only way out ran along an inside tile (a bubble, seen on
    # random samples), so it comes before the last topology pass, not after. That pass also
    # catches what smoothing did: closed thin outside tunnels (bubbles), cut inside necks (specks).
    if _lines(phi):
        from mpmfx.surface import line_kernels as L

        _blocks(wp, L.match_tiles_lines, [bcoord, bmap, phi, 1e-3])
    else:
        _split(wp, S.match_tiles, nvox, [bcoord, bmap, phi, 1e-3])
    seed = SEED_DEPTH_SMOOTHED if params.smooth_iters > 0 else SEED_DEPTH * grid.r_vox
    steps += _fix_topology(wp, T, bcoord, bmap, phi, mark, tiles, seed_depth=seed)
    if params.min_feature_particles > 0 and nvox:
        _remove_small(wp, T, bcoord, bmap, phi, gs, mark, params.min_feature_particles, tiles)
    values = wp.empty_like(phi)  # renormalising keeps every sign: the topology stands
    # a voxel the band's width or more from the zero level takes the band's value: phi is a
    # distance there already, but where the Eikonal sweeps stopped short of wide (on a slanted
    # face they converge only what is read: _eikonal_sweeps) it steps up to +-wide, and
    # phi / |grad phi| across that step read as near (a 30k random box "fast": 5 % of the leaves'
    # band voxels, 0.31 band off the distance to the mesh there on average, now 0.002). An
    # INSIDE tile reads as deep as the smoothing read it (flow_tiles), not -wide, which next to
    # a voxel 3 deep read as steep too (20k random box "fast": band voxels over half a voxel off
    # 391 -> 205; the same meshes)
    _renormalise(wp, S, bcoord, bmap, phi, flow_tiles, grid.voxel, grid.background, values, far=float(params.band_voxels))
    tiles = (grid.background, -grid.background)
    timings["smooth"] = _lap(wp, t0)
    mesh = _extract_mesh(wp, M, bcoord, bmap, values, tiles, vel if with_v else None, w, grid)
    timings["mesh"] = _lap(wp, t0)
    kind = wp.empty(max(nact, 1), dtype=wp.int32)
    _launch(wp, M.classify_output_blocks, nact, [values, grid.background, kind])
    log.debug("surface_sparse n=%d blocks=%s active=%d timings=%s", n, grid.nblocks, nact, timings)
    stats = {**timings, "active_blocks": nact, "fill_rounds": steps}
    return DeviceSurface(grid, n, bcoord, bmap, counts, values, w, vel if with_v else None, kind[:nact], mesh, stats)


def _lap(wp, t0: float) -> float:
    wp.synchronize()
    return round(time.perf_counter() - t0, 4)


def _launch(wp, kernel, dim: int, inputs: list) -> None:
    if dim:
        wp.launch(kernel, dim, inputs=inputs)


def _lines(a) -> bool:
    """Whether the kernels on `a`'s device take a block line per thread (mpmfx.surface.line_kernels:
    on the CPU, where a launch runs its threads one after another) or a voxel (on a GPU)."""
    return LINE_KERNELS_ON_CPU and a.device.is_cpu


def _renormalise(wp, S, bcoord, bmap, phi, tiles, scale: float, clip: float, out, *, far: float = NO_FAR) -> None:
    """out = sparse_kernels.renormalise of phi (a block line per thread on the CPU); |phi| of
    `far` or more gives +-clip."""
    from mpmfx.surface import line_kernels as L

    if _lines(phi):
        _blocks(wp, L.renormalise_lines, [bcoord, bmap, L.rows(phi), *tiles, scale, clip, far, L.rows(out)])
    else:
        _split(wp, S.renormalise, phi.shape[0], [bcoord, bmap, phi, *tiles, scale, clip, far, out])


def _blocks(wp, kernel, inputs: list, *, light: bool = False) -> None:
    """Launch a CPU-path kernel that takes a block per thread (inputs[0]: bcoord, the active
    blocks), split across CPU threads however few the blocks, or (light: a few hundred ns a
    block) from launch.LIGHT_MIN_SPLIT blocks on."""
    launch_split(wp, kernel, inputs[0].shape[0], inputs, device=inputs[0].device, min_split=1, light=int(light))


def _split(wp, kernel, dim: int, inputs: list) -> None:
    """Launch a kernel that takes a trailing `base` on the device of inputs[0], split across
    CPU threads on the CPU (mpmfx.surface.launch)."""
    launch_split(wp, kernel, dim, inputs, device=inputs[0].device)


def _scan(wp, a, *, inclusive: bool):
    out = wp.empty_like(a)
    wp.utils.array_scan(a, out, inclusive=inclusive)
    return out


def active_rounds(wp, T, bcoord, bmap, pending, sweep) -> tuple[int, bool]:
    """(rounds, settled): rounds of sweep(active, changed, moved) until one changes nothing, at
    most MAX_SWEEP_ROUNDS. The first sweeps the `pending` blocks (int32 flags), each later one
    only those where the previous round moved something, or next to one
    (topology_kernels.active_blocks: a block whose own values and face neighbours' did not move
    would sweep to what it holds). sweep sets changed[0] and moved[b] where it changes block b."""
    nact = bcoord.shape[0]
    changed = wp.zeros(1, dtype=wp.int32)
    active, moved, was = wp.empty(nact, dtype=wp.int32), wp.zeros(nact, dtype=wp.int32), wp.zeros(nact, dtype=wp.int32)
    for rounds in range(1, MAX_SWEEP_ROUNDS + 1):
        wp.launch(T.active_blocks, nact, inputs=[bcoord, bmap, pending, was, int(rounds == 1), active])
        changed.zero_()
        moved.zero_()
        sweep(active, changed, moved)
        moved, was = was, moved
        if int(changed.numpy()[0]) == 0:
            return rounds, True
    return MAX_SWEEP_ROUNDS, False


def _bin_particles(wp, S, g, grid: SparseGrid):
    """(counts per block (3-D int32), counts per gather cell (3-D, CELLS_PER_BLOCK per block and
    axis), first sorted slot per cell (flat), particle order sorted by cell)."""
    n = g.shape[0]
    counts = wp.zeros(grid.nblocks, dtype=wp.int32)
    cells = wp.zeros(tuple(b * CELLS_PER_BLOCK for b in grid.nblocks), dtype=wp.int32)
    cpu = _lines(g)
    keys = wp.empty(n if cpu else 2 * n, dtype=wp.int32)  # radix_sort_pairs sorts through a second half
    order = wp.empty(n if cpu else 2 * n, dtype=wp.int32)
    wp.launch(S.count_blocks, n, inputs=[g, counts, cells, keys, order])
    starts = _scan(wp, cells.flatten(), inclusive=False)
    if cpu:  # the radix sort's order from the cell counts in one pass (line_gather_kernels.counting_sort)
        from mpmfx.surface import line_gather_kernels as G

        wp.launch(G.counting_sort, 1, inputs=[keys, starts, wp.zeros(starts.shape[0], dtype=wp.int32), order])
    else:
        wp.utils.radix_sort_pairs(keys, order, n)
    return counts, cells, starts, order


def _sorted_positions(wp, S, g, order):
    """g in the gather cells' order (gs[q] = g[order[q]], (n,) vec3).

    The kernels that read a cell's particles (the gathers) then read consecutive memory instead
    of following `order`, and those that take one particle at a time in any order
    (mark_near_blocks, count_component_particles) touch the block map, the voxel arrays and the
    counters in space order: in the caller's order random samples (what simulated particles look
    like) jump from one block to the next, where a lattice's neighbours follow each other (100k
    random "fine", CPU, one thread: 1.4-2x those kernels' time on a lattice of the same shape;
    10M random torus "fine", one H200: the GPU gather 27.4 ms against 20.7 on the lattice).
    Their results do not depend on the order."""
    gs = wp.empty(g.shape[0], dtype=wp.vec3)
    _split(wp, S.sorted_copy, g.shape[0], [g, order, gs])
    return gs


def _mark_particle_voxels(wp, T, bcoord, bmap, cells, starts, gs):
    """The voxels nearest to a particle (the specks' seeds): a bit each in 8 words a block on
    the CPU (bitfill_kernels.mark_particle_bits, what the bit flood fills read), else an int32
    each (topology_kernels.mark_particle_voxels). gs: the grid positions (in the cells' order
    on the CPU: _sorted_positions)."""
    if _lines(gs):
        from mpmfx.surface import bitfill_kernels as F

        mark = wp.empty(max(bcoord.shape[0] * BS, 1), dtype=wp.uint64)
        _blocks(wp, F.mark_particle_bits, [bcoord, cells, starts, gs, mark])
        return mark
    mark = wp.zeros(max(bcoord.shape[0] * BS**3, 1), dtype=wp.int32)
    _split(wp, T.mark_particle_voxels, gs.shape[0], [gs, bmap, mark])  # writes 1s: any interleaving agrees
    return mark


def _field(wp, S, bcoord, bmap, cells, starts, order, gs, v, grid: SparseGrid, params: SurfaceParams):
    """The raw Zhu-Bridson field at the active voxels: (phi (voxels), kernel weight sums w,
    kernel-weighted velocity or a 1-element placeholder, the edges for the smoothing's limit
    (_edges; None without smoothing)), isotropic or with Yu & Turk's ellipsoids
    (params.anisotropic). gs: the particles' grid positions in the cells' order (_sorted_positions),
    v: their velocities in the caller's order (or None)."""
    from mpmfx.surface import line_gather_kernels as G
    from mpmfx.surface import line_kernels as L

    nvox = bcoord.shape[0] * BS**3
    with_v = v is not None
    phi, w = wp.empty(nvox, dtype=float), wp.empty(nvox, dtype=float)
    vel = wp.empty(nvox if with_v else 1, dtype=wp.vec3)
    if nvox == 0:
        return phi, w, vel, None
    offset = wp.empty(nvox, dtype=wp.vec3)
    aniso = params.anisotropic
    cov = wp.empty(nvox if aniso else 1, dtype=wp.mat33)
    radius = wp.empty(nvox if aniso else 1, dtype=float)
    n = gs.shape[0]
    vs = wp.empty(n if with_v else 1, dtype=wp.vec3)  # v in the cells' order, as gs
    if with_v:
        _split(wp, S.sorted_copy, n, [v, order, vs])
    if aniso:
        from mpmfx.surface import aniso_kernels as A
        gmat, thin = wp.empty(n, dtype=wp.mat33), wp.empty(n, dtype=float)
        wp.launch(A.particle_shape, n, inputs=[gs, cells, starts, grid.kernel_vox, ANISO_MAX_RATIO,
                                               ANISO_MAX_STRETCH, ANISO_MIN_NEIGHBOURS, gmat, thin])
        wp.launch(A.gather_zhu_bridson_aniso, nvox,
                  inputs=[bcoord, cells, starts, gs, gmat, thin, vs, int(with_v), grid.gather_vox, grid.kernel_vox,
                          grid.r_vox, grid.far_vox], outputs=[phi, w, offset, vel, cov, radius])
    elif _lines(phi):  # one thread per block: each candidate particle fetched once per block
        nacc = 10 if with_v else 7  # vec8 sums per line: w, offset, weight gradient (, velocity)
        launch_split_scratch(wp, G.gather_zhu_bridson_blocks, bcoord.shape[0],
                             [bcoord, cells, starts, gs, vs, int(with_v), grid.kernel_vox, grid.r_vox, grid.far_vox, phi, w,
                              offset, vel, nacc, int(grid.normal_passes == 0)],  # else phi comes from the wide normal below
                             lambda: wp.empty((BS * BS, nacc), dtype=L.vec8), device=phi.device)
    else:
        wp.launch(S.gather_zhu_bridson, nvox,
                  inputs=[bcoord, cells, starts, gs, vs, int(with_v), grid.kernel_vox, grid.r_vox, grid.far_vox],
                  outputs=[phi, w, offset, vel])
    wide = w
    if grid.normal_passes > 0:
        wide = _blur_weights(wp, S, bcoord, bmap, w, grid.normal_passes)
        if _lines(phi) and not aniso:
            _blocks(wp, L.project_on_wide_normal_lines, [bcoord, bmap, wide, w, offset, grid.r_vox, grid.far_vox, phi])
        else:
            _split(wp, S.project_on_wide_normal, nvox, [bcoord, bmap, wide, w, offset, grid.r_vox, grid.far_vox, int(aniso),
                                                        cov, ANISO_NORMAL_ITERS, ANISO_COV_EPS * grid.kernel_vox**2, radius, phi])
    edges = _edges(wp, bcoord, bmap, wide, offset, phi, grid) if params.smooth_iters > 0 else None
    return phi, w, vel, edges


def _edges(wp, bcoord, bmap, wide, offset, phi, grid: SparseGrid) -> tuple:
    """(gate per 2^3-voxel cell, noise per active block, sample per cell) for the smoothing's inward limit
    (mpmfx.surface.edge_kernels): where the blurred weights' level set bends like an edge, and
    how noisy the samples are around each block (voxels). `wide`: the weights the normal came
    from, of blur width grid.wide_sigma voxels."""
    from mpmfx.surface import edge_kernels as E

    nact = bcoord.shape[0]
    gate, sample = wp.empty(nact * 64, dtype=float), wp.empty(nact * 64, dtype=float)  # a 2^3-voxel cell each
    k0, k1 = (c / grid.wide_sigma for c in EDGE_CURVATURE)
    _split(wp, E.edge_gate, nact * 64, [bcoord, bmap, wide, offset, phi, EDGE_BAND, k0, k1, gate, sample])
    sums, noise = wp.empty(nact, dtype=wp.vec2), wp.empty(nact, dtype=float)
    _split(wp, E.block_samples, nact, [sample, sums])
    _split(wp, E.block_noise, nact, [bcoord, bmap, sums, EDGE_NOISE, noise])
    return gate, noise, sample  # sample < 0 where a gate is open: a corner or a blob (_sharpen)


def _classify(wp, S, gs, counts, cells, starts, grid: SparseGrid):
    """(bmap: block -> active index or tile code, bcoord: (m,) vec3i active block coordinates,
    the block flood fill's labels where there are voids, else None: _settle_voids);
    cells, starts: the gather cells' particles (_bin_particles), gs: their grid positions in the
    cells' order (_sorted_positions)."""
    near = wp.zeros(grid.nblocks, dtype=wp.int32)
    if _lines(gs):  # a block of particles per thread, most blocks decided without their particles
        from mpmfx.surface import near_blocks_cpu as N

        nb = math.prod(grid.nblocks)
        # a grid block per thread, much work for those holding particles: split however few the
        # blocks (MIN_SPLIT left these unsplit below 16384 blocks, 10976 at the 100k torus "fine")
        kw = {"device": gs.device, "min_split": 1}
        launch_split(wp, N.mark_near_certain, nb, [cells, grid.reach_vox, near], **kw)
        launch_split(wp, N.mark_near_tested, nb, [cells, starts, gs, grid.reach_vox, near], **kw)
    else:
        _split(wp, S.mark_near_blocks, gs.shape[0], [gs, grid.reach_vox, near])  # writes 1s: any interleaving agrees
    state = wp.empty(grid.nblocks, dtype=wp.int32)
    wp.launch(S.classify_blocks, grid.nblocks, inputs=[counts, near, grid.dense_reach, grid.dense_min, state])
    labels = wp.empty(grid.nblocks, dtype=wp.int32)
    wp.launch(S.outside_block_labels, grid.nblocks, inputs=[state, labels])
    _sweep_block_labels(wp, S, labels)
    voids = _settle_voids(wp, S, labels, state, grid)
    flags = wp.empty(math.prod(grid.nblocks), dtype=wp.int32)
    wp.launch(S.active_flags, grid.nblocks, inputs=[state, flags])
    offsets = _scan(wp, flags, inclusive=False)
    nact = int(offsets[-1:].numpy()[0] + flags[-1:].numpy()[0])
    bmap = wp.empty(grid.nblocks, dtype=wp.int32)
    bcoord = wp.empty(max(nact, 1), dtype=wp.vec3i)
    wp.launch(S.compact_blocks, grid.nblocks, inputs=[state, offsets, bmap, bcoord])
    return bmap, bcoord[:nact], voids


def _settle_voids(wp, S, labels, state, grid: SparseGrid):
    """Voids, the OUTSIDE blocks the grid boundary does not reach (`labels` above 0, one label a
    void), may be sealed air (a bubble in a body, a hollow shell's cavity: filled) or the open
    space between sparse particles (spray, open through gaps narrower than a block). The voxels
    tell them apart, so each void's blocks next to any other block (its shell) become ACTIVE,
    and the rest (its core) an INSIDE tile, until _open_void_cores reads the shell after the
    bubble fill. As INSIDE tiles whole, an open void became a phantom body: 120 drops on a
    sphere 7.6 h apart surfaced as 121 pieces, a ball 10-12 h from every particle among them
    (test_sparse). Made ACTIVE whole, a void costs in proportion to its volume (a lattice shell
    0.28-0.30 m of a 0.3 m ball: 1.8x the call), its shell only to its area. Returns `labels`
    where there are voids, else None; `state` is updated in place."""
    count = wp.zeros(1, dtype=wp.int32)
    wp.launch(S.count_voids, grid.nblocks, inputs=[labels, count])
    if int(count.numpy()[0]) == 0:
        return None
    wp.launch(S.void_shells, grid.nblocks, inputs=[labels, state])
    return labels


def _open_void_cores(wp, S, bmap, phi, voids) -> None:
    """After the bubble fill (_fix_topology): the core of each void (`voids`: _settle_voids'
    labels) whose shell holds an outside voxel (open: its air joins the outside) becomes
    OUTSIDE; a sealed void's core stays INSIDE, as its shell was filled."""
    open_ = wp.zeros(math.prod(bmap.shape) + 1, dtype=wp.int32)  # by label: a block's linear index + 1
    wp.launch(S.void_openness, bmap.shape, inputs=[voids, bmap, phi, open_])
    wp.launch(S.open_void_cores, bmap.shape, inputs=[voids, open_, bmap])


def _sweep_block_labels(wp, S, labels) -> int:
    """Run +-x, +-y, +-z label sweeps over the block grid until no label changes; returns the
    rounds used."""
    changed = wp.zeros(1, dtype=wp.int32)
    n = labels.shape
    for rounds in range(1, MAX_BLOCK_SWEEP_ROUNDS + 1):
        changed.zero_()
        for axis in range(3):
            others = tuple(n[a] for a in range(3) if a != axis)
            for rev in (0, 1):
                wp.launch(S.sweep_block_labels, others, inputs=[labels, axis, rev, changed])
        if int(changed.numpy()[0]) == 0:
            return rounds
    log.warning("block label sweeps did not settle in %d rounds; some voids may remain", MAX_BLOCK_SWEEP_ROUNDS)
    return MAX_BLOCK_SWEEP_ROUNDS


def _fix_topology(wp, T, bcoord, bmap, phi, mark, tiles, *, seed_depth: float) -> int:
    """Fill bubbles (outside voxels the boundary does not reach), then turn inside specks that
    hold no particle at least seed_depth deep to outside; returns the sweep rounds used.
    Bubbles first: a speck inside a bubble is then part of the body, and a speck turned outside
    joins an outside region the boundary reaches, so neither step undoes the other."""
    if phi.shape[0] == 0:
        return 0
    rounds = _flood(wp, T, bcoord, bmap, phi, mark, tiles, seed_depth, specks=False)
    rounds += _flood(wp, T, bcoord, bmap, phi, mark, tiles, seed_depth, specks=True)
    return rounds


def _flood(wp, T, bcoord, bmap, phi, mark, tiles, seed_depth: float, *, specks: bool) -> int:
    if _lines(phi):  # bit words, a block per thread filled to its fixpoint each round (CPU)
        from mpmfx.surface import topology_cpu as C

        _, reached, rounds = C.flood_bits(wp, T, bcoord, bmap, phi, mark, seed_depth, "specks" if specks else "bubbles")
        C.flip_unreached(wp, reached, phi, tiles)
        return rounds
    nvox = phi.shape[0]
    reached = wp.empty(nvox, dtype=wp.int32)
    pending = wp.zeros(bcoord.shape[0], dtype=wp.int32)
    _split(wp, T.seed_reached, nvox, [bcoord, bmap, phi, mark, seed_depth, int(specks), reached, pending])

    def sweep(active, changed, moved):
        for axis in range(3):
            _split(wp, T.sweep_reached, bcoord.shape[0] * 64, [bcoord, bmap, phi, reached, active, axis, changed, moved])

    rounds, settled = active_rounds(wp, T, bcoord, bmap, pending, sweep)  # all pending blocks first, then near what moved
    if not settled:
        log.warning("topology flood fill did not settle in %d rounds; some bubbles may remain", MAX_SWEEP_ROUNDS)
    # unreached outside voxels are bubbles (-> inside), unreached inside ones specks (-> outside)
    wp.launch(T.flip_unreached, nvox, inputs=[phi, reached, tiles[1], tiles[0]])
    return rounds


def _remove_small(wp, T, bcoord, bmap, phi, g, mark, min_count: int, tiles) -> None:
    """Inside components (6-connected) holding fewer than min_count particles become outside;
    components touching an INSIDE tile are large by construction and stay, and so are those
    holding a block whose inside voxels are one piece with at least min_count particles'
    voxels (bitfill_kernels.large_piece: on the CPU they seed the bodies' fill, on a GPU they
    start the min-label sweeps at 0, which a water sheet with no INSIDE tile needs: a 1M
    random sheet on an H200 took 158 rounds and 271 ms of sweeps, now 4 rounds and 7 ms)."""
    nvox = phi.shape[0]
    if _lines(phi):
        from mpmfx.surface import topology_cpu as C

        labels = C.small_labels(wp, T, bcoord, bmap, phi, mark, min_count)
        if labels is None:  # no small component
            return
    else:
        from mpmfx.surface import bitfill_kernels as F

        labels = wp.empty(nvox, dtype=wp.int32)
        _split(wp, T.init_inside_labels, nvox, [bcoord, bmap, phi, labels])
        _split(wp, F.seed_large_labels, bcoord.shape[0], [phi, mark, min_count, labels])

        def sweep(active, changed, moved):
            for axis in range(3):
                _split(wp, T.sweep_min_labels, bcoord.shape[0] * 64, [bcoord, bmap, labels, active, axis, changed, moved])

        # the rounds over the blocks near the last round's changes (hero_dam frame 8 on an H200: its
        # thin parts take 34 rounds, most of its blocks settled after a few: labels 28 -> 8 ms)
        active_rounds(wp, T, bcoord, bmap, wp.full(bcoord.shape[0], 1, dtype=wp.int32), sweep)
    counts = wp.zeros(nvox + 1, dtype=wp.int32)
    wp.launch(T.count_component_particles, g.shape[0], inputs=[g, bmap, labels, counts])
    _split(wp, T.remove_small_components, nvox, [labels, counts, min_count, tiles[0], phi])


def _blur_weights(wp, S, bcoord, bmap, w, passes: int):
    """The kernel weight sums blurred `passes` times along each axis (a new array)."""
    from mpmfx.surface import line_kernels as L

    # the first pass reads w itself (no copy of it: 8 MB at 100k "fine"), then two buffers take turns
    a, b = w, wp.empty_like(w)
    steps = []
    for _ in range(passes):
        for axis in range(3):
            if _lines(w) and NORMAL_STEP == 2:  # the line kernel is written out for step 2
                steps.append((L.blur_weight_lines, [bcoord, bmap, L.rows(a), axis, L.rows(b)]))
            else:  # a line each
                steps.append((S.blur_weight_axis, [bcoord, bmap, a, axis, NORMAL_STEP, b]))
            a, b = b, (wp.empty_like(w) if a is w else a)
    dim = bcoord.shape[0] * (1 if _lines(w) else BS * BS)
    # 21 light passes at the shots' setting (0.4-0.5 ms each at 100k "fine"): split, each would pay
    # a hand-off to the pool; as a sequence, one (the lattice torus "fine" 2.3-3.4 ms less a call)
    launch_sequence(wp, steps, dim, device=w.device, min_split=BLUR_MIN_SPLIT)
    return a


def _distance(wp, S, bcoord, bmap, phi, tiles, clip: float, read: float):
    """The raw field as a distance (voxels, clipped to +-clip) that blurs without moving its zero
    level. phi / |grad phi| has slope 1 at the zero level but, where phi is convex across the
    surface (Zhu-Bridson is), the opposite curvature of phi itself, so a blur moves the surface
    outward as far as it would move the raw field inward (0.3-0.5 % volume per pass, measured).
    Renormalising that once more flips the curvature back; the mean of the two is straight to
    second order."""
    from mpmfx.surface import line_kernels as LK
    from mpmfx.surface import line_redistance_kernels as L
    from mpmfx.surface import redistance_kernels as R

    nvox = phi.shape[0]
    d1, d2 = wp.empty_like(phi), wp.empty_like(phi)
    _renormalise(wp, S, bcoord, bmap, phi, tiles, 1.0, clip, d1)
    if nvox == 0:
        return d1
    # the raw field is a distance only near its zero level (it flattens to -r inside, and the
    # renormalised values there are no distance either): keep its zero crossings, start the
    # voxels next to them at their distance to the plane through the axis crossings
    # (redistance_kernels.init_eikonal, plane = 1: the field's own slope there is not 1, and a
    # kink at the crossing moved flat faces out under the blur), and recompute the rest of the
    # band from them (|grad phi| = 1). Without it each blur pass that reached the flat part
    # moved lattice surfaces outward (sphere +0.08 h at five passes).
    frozen = wp.empty(nvox, dtype=wp.int32)
    a, b = wp.empty_like(phi), wp.empty_like(phi)
    was = wp.empty(nvox // 64, dtype=wp.uint64)  # voxels changed by a sweep, a bit each (CPU)
    fbits = wp.empty(nvox // 64, dtype=wp.uint64)  # the frozen voxels, a bit each (CPU)
    if _lines(phi):  # the second renormalise and the average in one pass, with the frozen flags
        _blocks(wp, L.crossing_average_lines, [bcoord, bmap, LK.rows(d1), clip, frozen, LK.rows(d2)])
        _blocks(wp, L.init_eikonal_lines, [bcoord, bmap, d2, clip, 1, 0, frozen, a, b, was, fbits])
    else:
        _renormalise(wp, S, bcoord, bmap, d1, (clip, -clip), 1.0, clip, d2)
        _launch(wp, S.average_into, nvox, [d1, d2])
        _split(wp, R.init_eikonal, nvox, [bcoord, bmap, d1, clip, -clip, clip, 1, frozen, a])
    return _eikonal_sweeps(wp, bcoord, bmap, a, b, frozen, was, fbits, clip, read)


def _redistance(wp, bcoord, bmap, phi, clip: float, read: float):
    """phi's zero level with a distance around it (a new array, voxels, clipped to +-clip): the
    voxels next to the crossing keep theirs (capped at the crossing interpolated along an axis),
    the rest of the band comes from the Eikonal sweeps, as in _distance (tiles read +-clip)."""
    from mpmfx.surface import line_redistance_kernels as L
    from mpmfx.surface import redistance_kernels as R

    nvox = phi.shape[0]
    frozen = wp.empty(nvox, dtype=wp.int32)
    a, b = wp.empty_like(phi), wp.empty_like(phi)
    was = wp.empty(nvox // 64, dtype=wp.uint64)
    fbits = wp.empty(nvox // 64, dtype=wp.uint64)
    if _lines(phi):  # the frozen flags found too, into both sweep buffers, with the changed bits the line sweeps start from
        _blocks(wp, L.init_eikonal_lines, [bcoord, bmap, phi, clip, 0, 1, frozen, a, b, was, fbits])
    else:
        _split(wp, R.init_eikonal, nvox, [bcoord, bmap, phi, clip, -clip, clip, 0, frozen, a])
    return _eikonal_sweeps(wp, bcoord, bmap, a, b, frozen, was, fbits, clip, read)


def _eikonal_sweeps(wp, bcoord, bmap, a, b, frozen, was, fbits, clip: float, read: float):
    """Jacobi sweeps of |grad phi| = 1 from the initial distance a (b: the second buffer; on the
    CPU a copy of a, `was` the voxels init set, fbits the frozen ones a bit per voxel), until
    the values within `read` voxels of the zero level are what more sweeps give, to rounding.
    A sweep advances one voxel along each axis, so from the frozen voxels (within one of the
    zero level) a face at any slant is converged to read after sqrt(3) (read - 1) sweeps, and
    along an axis to clip after clip sweeps; further out the values step up to +-clip
    (the final renormalise keeps those at the band's value). The shots' setting takes 7 sweeps
    where it took 10 (to clip along an axis): values 2 voxels out move by 1e-5 voxel, vertices by
    at most 4e-4 h (30k bench cases, the splash frame); the 100k lattice torus "fine" call
    94-99 -> 88-92 ms on two threads."""
    from mpmfx.surface import line_kernels as LK
    from mpmfx.surface import line_redistance_kernels as L
    from mpmfx.surface import redistance_kernels as R

    nvox = a.shape[0]
    now = wp.empty(nvox // 64, dtype=wp.uint64)
    for sweep in range(min(int(math.ceil(clip)), int(math.ceil(math.sqrt(3.0) * (read - 1.0)))) + 1):
        if _lines(a):
            _blocks(wp, L.eikonal_lines, [bcoord, bmap, LK.rows(a), fbits, clip, -clip, clip, LK.rows(b), was, now])
            was, now = now, was
        else:
            _split(wp, R.eikonal_sweep, nvox // BS, [bcoord, bmap, a, frozen, clip, -clip, clip, b])  # a line each
        a, b = b, a
    return a


def _close_voids(wp, S, bcoord, bmap, dist, rho: float, clip: float):
    """The morphological closing of the inside of the distance `dist` (voxels, +-clip) by a ball
    of radius rho voxels, as a distance (a new array): grown by rho, redistanced, shrunk by rho.
    Dents a ball of radius rho cannot enter from outside (the voids of random samples) fill;
    convex edges stay as they are, where the blur that follows fills dents only while it rounds
    them (SurfaceParams.close_voids; docs/surfacing-log.md, "Closing the sample voids").
    Only where the closing fills by more than CLOSE_GATE[0] x rho (in full from CLOSE_GATE[1] x
    rho, a ramp between so that a fill growing between frames does not jump): on the grid, grow-redistance-
    shrink is not the identity on a flat face. It moved a lattice box's faces out uniformly
    by 0.03 h ("fine") to 0.05 h ("fast") at rho = h (the raw field's own dimples are 0.008 h on a
    cubic lattice's (100) face, 0.03 h on (110)), and it eroded convex edges by up to 0.2 h
    (dist - closed down to -0.46 voxel), which made the lattice box 0.023 -> 0.034 h ("fast").
    The voids it should fill move the distance 0.2-1.5 h. Gated, the lattice rows stay as
    without the closing and random samples keep most of its gain (100k "fast" sphere
    0.121 -> 0.114 h; 2-core CPU; a step gate anywhere in 0.06-0.15 rho gives the same to 0.002 h)."""
    grown = wp.clone(dist)
    _launch(wp, S.add_scalar, grown.shape[0], [grown, -rho])
    # converged to its clip, as before: the gate compares it with dist wherever the closing fills,
    # and at 10 sweeps instead of 12 random samples' vertices moved 0.008 h
    closed = _redistance(wp, bcoord, bmap, grown, clip + rho, clip + rho)
    _launch(wp, S.add_clamp, closed.shape[0], [closed, rho, clip])
    _launch(wp, S.gate_closing, closed.shape[0], [closed, dist, CLOSE_GATE[0] * rho, CLOSE_GATE[1] * rho])
    return closed


def _smooth(wp, S, bcoord, bmap, dist, iters: int, tiles, *, limit: float, edges: tuple):
    """`iters` steps of the level set's mean-curvature flow over the distance `dist` (kept;
    sparse_kernels.curvature_flow, FLOW_DT voxel^2 a step, values within FLOW_BAND of the zero
    level), the surface then moved at most `limit` voxels inward, and at an edge at most
    EDGE_NOISE x the noise of its samples (`edges`: _edges' gate and noise; on a lattice the raw
    field already holds an edge, and the flow only rounded it: 100k lattice box 0.027 / 0.033 ->
    0.016 / 0.020 h, docs/surfacing-log.md, eighteenth step). The flow averages the
    surface's noise on random samples away, as a [1 2 1]/4 blur along each axis did, but only
    along the surface: the blur's Laplacian also averaged across it, so it ate into anything
    thinner than it was wide, and pinched the gaps of a random sheet into more holes. 2-core
    CPU, 100k particles, mean error in h at the same count (random sphere / torus / box, "fine",
    8 steps): blur 0.0884 / 0.0939 / 0.1172, flow 0.0915 / 0.0959 / 0.1185; the random thin sheet's
    holes at 8 steps: blur 540 (anisotropic 250), flow 97 (2), and with "fine"'s 5 blur passes
    463 (136) (docs/surfacing-log.md, "Smoothing along the surface"). The limit keeps the flow
    from shrinking a drop or a filament away (half thickness ~r). Outward it is free: that is
    how the dents of sample voids fill."""
    from mpmfx.surface import line_kernels as L

    if iters == 0 or dist.shape[0] == 0:  # no active voxel: no edges measured either (_field)
        return dist
    gate, noise, _ = edges
    phi, tmp = dist, wp.empty_like(dist)  # the first step reads dist itself (kept: no copy), then two buffers take turns
    for _ in range(iters):
        if _lines(phi):
            _blocks(wp, L.curvature_flow_lines, [bcoord, bmap, L.rows(phi), *tiles, FLOW_DT, FLOW_BAND, L.rows(tmp)])
            _blocks(wp, L.edge_flow_lines, [bcoord, bmap, L.rows(phi), *tiles, FLOW_DT, FLOW_BAND, gate, EDGE_PIT, L.rows(tmp)])
        else:  # a line each
            _split(wp, S.curvature_flow, phi.shape[0] // BS, [bcoord, bmap, phi, *tiles, FLOW_DT, FLOW_BAND, tmp])
            _split(wp, S.edge_flow, gate.shape[0], [bcoord, bmap, phi, *tiles, FLOW_DT, FLOW_BAND, gate, EDGE_PIT, tmp])
        phi, tmp = tmp, (wp.empty_like(dist) if phi is dist else phi)
    if _lines(phi):
        _blocks(wp, L.limit_inward_lines, [bcoord, L.rows(phi), L.rows(dist), limit, gate, noise])
    else:
        _split(wp, S.limit_inward, phi.shape[0], [phi, dist, limit, gate, noise])
    return phi


def _sharpen(wp, bcoord, bmap, phi, tiles, gate, sample, h: float) -> None:
    """Convex edges and corners of the smoothed field `phi` made sharp again, in place
    (mpmfx.surface.sharp_kernels; SHARP's settings; gate, sample: _edges'; h: the particle
    spacing in voxels). The cells whose edge gate is open and that lie near the zero level are
    numbered (a scan); every other one of them on each axis, and every corner, finds the faces
    around it; each takes its neighbours' faces' intersection where they form a convex edge or
    corner. A body with no open gate costs a launch over its cells and one host read."""
    from mpmfx.surface import sharp_kernels as K

    ncell = gate.shape[0]
    if ncell == 0:
        return
    c = SHARP
    flags = wp.empty(ncell, dtype=wp.int32)
    _split(wp, K.flag_cells, ncell, [bcoord, bmap, phi, *tiles, gate, c["band"], c["thin"] * h, flags])
    slots = _scan(wp, flags, inclusive=False)
    count = int(slots[ncell - 1 : ncell].numpy()[0] + flags[ncell - 1 : ncell].numpy()[0])
    if count == 0:
        return
    cells = wp.empty(count, dtype=wp.int32)
    pn, pp = wp.empty(count * K.CELL_PLANES, dtype=wp.vec3), wp.empty(count * K.CELL_PLANES, dtype=wp.vec3)
    pw = wp.empty(count * K.CELL_PLANES, dtype=float)
    _split(wp, K.cell_planes, ncell, [bcoord, bmap, phi, *tiles, sample, flags, slots, c["near"] * h, c["far"] * h,
                                      c["width"] * h, c["cos_flat"], c["plane_tol"] * h, c["cos_same"], cells, pn, pp, pw])
    qn, qp = wp.empty(count * K.NEAR_PLANES, dtype=wp.vec3), wp.empty(count * K.NEAR_PLANES, dtype=wp.vec3)
    qw = wp.empty(count * K.NEAR_PLANES, dtype=float)
    state = wp.empty(count, dtype=wp.int32)
    launch_split(wp, K.decide_cells, count, [bcoord, bmap, sample, flags, slots, cells, pn, pp, pw, c["cos_same"],
                                             c["votes"], c["support"], c["cos_apart"], c["cos_open"], qn, qp, qw, state],
                 device=phi.device, min_split=256)  # a few hundred cells already: each thread does much
    launch_split(wp, K.sharpen_cells, count, [bcoord, bmap, phi, gate, flags, slots, cells, state, c["votes"],
                                              c["limit"] * h, c["rounding"], c["spread"], qn, qp, qw],
                 device=phi.device, min_split=256)  # a few hundred cells already: each thread does much


def _extract_mesh(wp, M, bcoord, bmap, values, tiles, vel, w, grid: SparseGrid) -> tuple | None:
    """Marching cubes over active cells: (world, normals, velocities, faces) device arrays of
    exact size, or None for an empty surface (w: the kernel weight sums, which say where the
    velocity field vel holds a velocity)."""
    from mpmfx.surface.mc_tables import device_tables

    nvox = values.shape[0]
    if nvox == 0:
        return None
    dev = values.device
    # a thread per edge and per cell (GPU), or per block (CPU), counted per edge and cell (GPU) or
    # per block line along z (its 24 edges and 8 cells)
    from mpmfx.surface import line_kernels as LK
    from mpmfx.surface import line_mesh_kernels as L

    if _lines(values):  # the corner signs once per line: 9 bits each (L.sign_columns)
        kv, kf, nv, nf = L.mc_vertices_lines, L.mc_faces_lines, nvox // BS, nvox // BS
        masks = wp.empty(nvox // BS, dtype=wp.int32)
        _blocks(wp, L.sign_columns, [bcoord, bmap, LK.rows(values), *tiles, masks], light=True)
        vin, fin = [values, *tiles, masks], [masks, *tiles]

        def run(kernel, dim, inputs):
            _blocks(wp, kernel, inputs)
    else:
        kv, kf, nv, nf = M.mc_vertices, M.mc_faces, nvox * 3, nvox
        vin = fin = [values, *tiles]

        def run(kernel, dim, inputs):
            _split(wp, kernel, dim, inputs)
    ecount = wp.empty(nv, dtype=wp.int32)
    edge_vert = wp.empty(nvox * 3, dtype=wp.int32)
    run(kv, nv, [bcoord, bmap, *vin, ecount, 1, ecount, edge_vert, None])
    eoff = _scan(wp, ecount, inclusive=True)
    tables = list(device_tables(wp, dev))
    fcount = wp.empty(nf, dtype=wp.int32)
    run(kf, nf, [bcoord, bmap, *fin, edge_vert, *tables, fcount, 1, fcount, None])
    foff = _scan(wp, fcount, inclusive=True)
    m, k = (int(a[-1:].numpy()[0]) for a in (eoff, foff))  # the two sizes: one sync each
    if m == 0 or k == 0:
        return None
    verts = wp.empty(m, dtype=wp.vec3)
    run(kv, nv, [bcoord, bmap, *vin, eoff, 0, ecount, edge_vert, verts])
    faces = wp.empty(3 * k, dtype=wp.int32)
    run(kf, nf, [bcoord, bmap, *fin, edge_vert, *tables, foff, 0, fcount, faces])
    world, normals, velocities = (wp.empty(m, dtype=wp.vec3) for _ in range(3))
    vel_arg = vel if vel is not None else wp.zeros(1, dtype=wp.vec3)
    origin = wp.vec3(*grid.origin.astype(np.float32))
    _split(wp, M.sample_vertices, m, [bmap, values, *tiles, vel_arg, w, int(vel is not None), verts, origin, grid.voxel,
                                      world, normals, velocities])
    return world, normals, velocities, faces
