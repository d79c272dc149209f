"""Output pass: the result's host copies. The mesh, the level set as OpenVDB-style leaves
(with velocity and fog density) and the optional dense arrays; the blocks' output kinds.

GPU: the kept blocks compacted on the device, then copied (into page-locked buffers,
:mod:`mpmfx.surface.pinned`). CPU: the arrays already live on the host; numpy takes the kept
blocks out a whole block at a time.
"""

from __future__ import annotations

import logging

import numpy as np
import warp as wp

from mpmfx.surface.launch import launch_nonempty, scan
from mpmfx.surface.params import LevelSet, SparseLevelSet, SurfaceMesh, SurfaceParams, SurfaceResult, kernel_volume
from mpmfx.surface.pinned import to_host
from mpmfx.surface.voxels import BS, BV, TILE_INSIDE, voxel_of

# forward only: nothing differentiates these kernels; their adjoint code would only lengthen the compile
wp.set_module_options({"enable_backward": False})

log = logging.getLogger(__name__)


@wp.kernel
def classify_output_blocks(values: wp.array(dtype=float), background: float, kind: wp.array(dtype=wp.int32)):
    """kind = 0: every voxel +background (drop), 1: every voxel -background (an inside tile), 2: keep."""
    b = wp.tid()
    n_out = int(0)
    n_in = int(0)
    for q in range(BV):
        v = values[b * BV + q]
        if v >= background:
            n_out += 1
        elif v <= -background:
            n_in += 1
    k = int(2)
    if n_out == BV:
        k = 0
    elif n_in == BV:
        k = 1
    kind[b] = k


@wp.kernel
def densify(
    bcoord: wp.array(dtype=wp.vec3i), data: wp.array(dtype=float), lo: wp.vec3i, dense: wp.array3d(dtype=float)
):
    """Copy active voxels into a dense array whose [0, 0, 0] is voxel `lo` (pre-filled with tiles)."""
    t = wp.tid()
    c = voxel_of(t, bcoord) - lo
    dense[c[0], c[1], c[2]] = data[t]


@wp.kernel
def densify_vec(
    bcoord: wp.array(dtype=wp.vec3i), data: wp.array(dtype=wp.vec3), lo: wp.vec3i, dense: wp.array3d(dtype=wp.vec3)
):
    t = wp.tid()
    c = voxel_of(t, bcoord) - lo
    dense[c[0], c[1], c[2]] = data[t]


@wp.kernel
def fill_tiles(
    bmap: wp.array3d(dtype=wp.int32), blo: wp.vec3i, out_v: float, in_v: float, dense: wp.array3d(dtype=float)
):
    """Constant-tile value of every voxel of the dense array (active voxels are overwritten)."""
    i, j, k = wp.tid()
    s = bmap[blo[0] + i // BS, blo[1] + j // BS, blo[2] + k // BS]
    dense[i, j, k] = wp.where(s == TILE_INSIDE, in_v, out_v)


@wp.kernel
def gather_blocks(
    keep: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    values: wp.array(dtype=float),
    out: wp.array(dtype=float),
):
    """Copy the voxels of kept blocks (keep[b] == 1) to their compacted slots."""
    t = wp.tid()
    b = t // BV
    if keep[b] != 0:
        out[offsets[b] * BV + t - b * BV] = values[t]


@wp.kernel
def gather_blocks_vec(
    keep: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    values: wp.array(dtype=wp.vec3),
    out: wp.array(dtype=wp.vec3),
):
    t = wp.tid()
    b = t // BV
    if keep[b] != 0:
        out[offsets[b] * BV + t - b * BV] = values[t]


@wp.kernel
def count_negative(a: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32)):
    """count[0] += the entries of a below 0 (count zeroed by the caller)."""
    t = wp.tid()
    if a[t] < 0:
        wp.atomic_add(count, 0, 1)


@wp.kernel
def inside_tiles(bmap: wp.array3d(dtype=wp.int32), flags: wp.array(dtype=wp.int32)):
    """flags = 1 on INSIDE tiles of the block grid, flattened in C order (as numpy's argwhere)."""
    i, j, k = wp.tid()
    flags[(i * bmap.shape[1] + j) * bmap.shape[2] + k] = wp.where(bmap[i, j, k] == TILE_INSIDE, 1, 0)


@wp.kernel
def compact_inside_tiles(
    bmap: wp.array3d(dtype=wp.int32),
    flags: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    out: wp.array(dtype=wp.vec3i),
):
    """out[offsets[b]] = the block coordinates of INSIDE tile b (exclusive scan of flags)."""
    i, j, k = wp.tid()
    b = (i * bmap.shape[1] + j) * bmap.shape[2] + k
    if flags[b] != 0:
        out[offsets[b]] = wp.vec3i(i, j, k)


@wp.kernel
def scan_totals(
    flags: wp.array(dtype=wp.int32), offsets: wp.array(dtype=wp.int32), slot: int, out: wp.array(dtype=wp.int32)
):
    """out[slot] = the sum of flags, from its exclusive scan (one thread)."""
    n = flags.shape[0]
    out[slot] = offsets[n - 1] + flags[n - 1]


@wp.kernel
def kind_equals(kind: wp.array(dtype=wp.int32), value: int, out: wp.array(dtype=wp.int32)):
    b = wp.tid()
    out[b] = wp.where(kind[b] == value, 1, 0)


@wp.kernel
def scale_clamp01(a: wp.array(dtype=float), scale: float):
    """a = clamp(a * scale, 0, 1): a kernel weight sum over its bulk value -> fog density."""
    t = wp.tid()
    a[t] = wp.clamp(a[t] * scale, 0.0, 1.0)


def output_kinds(values, background: float, nact: int):
    """(nact,) int32 per active block: 0 all-outside, 1 all-inside, 2 holds the band."""
    kind = wp.empty(max(nact, 1), dtype=wp.int32)
    launch_nonempty(wp, classify_output_blocks, nact, [values, background, kind])
    return kind[:nact]


@wp.kernel
def to_half(a: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3h)):
    t = wp.tid()
    out[t] = wp.vec3h(a[t])


def mesh_by_voxel(mesh: tuple | None, *, with_v: bool, pinned: bool, half: bool = False) -> SurfaceMesh:
    """The mesh on the host, its triangles with a -1 corner counted on the device; half: normals
    and velocities converted to float16 there (SurfaceParams.half_attributes)."""
    if mesh is not None and half:
        world, normals, velocities, faces = mesh
        halves = [
            None if a is None else wp.empty(a.shape[0], dtype=wp.vec3h)
            for a in (normals, velocities if with_v else None)
        ]
        for a, h in zip((normals, velocities), halves):  # (velocities: zeros when not with_v, made on the host)
            if h is not None:
                launch_nonempty(wp, to_half, a.shape[0], [a, h])
        mesh = (world, *halves, faces)
    return _halves(_download_mesh(mesh, with_v=with_v, pinned=pinned, on_host=False), half)


def mesh_by_block(mesh: tuple | None, *, with_v: bool, pinned: bool, half: bool = False) -> SurfaceMesh:
    """mesh_by_voxel, the triangles with a -1 corner found on the host (and the halves made there)."""
    return _halves(_download_mesh(mesh, with_v=with_v, pinned=pinned, on_host=True), half)


def _halves(m: SurfaceMesh, half: bool) -> SurfaceMesh:
    if half:  # (no copy of what the device converted)
        m.normals, m.velocities = m.normals.astype(np.float16, copy=False), m.velocities.astype(np.float16, copy=False)
    return m


def _download_mesh(mesh: tuple | None, *, with_v: bool, pinned: bool, on_host: bool) -> SurfaceMesh:
    if mesh is None:
        return SurfaceMesh.empty()
    world, normals, velocities, faces = mesh
    # a crossing on a tile face leaves a triangle a -1 corner (match_tiles should make that
    # impossible): on a GPU counted there, where a host pass over the faces costs 3 ms at 10M
    bad = None
    if not on_host:
        bad = wp.zeros(1, dtype=wp.int32, device=faces.device)
        launch_nonempty(wp, count_negative, faces.shape[0], [faces, bad])
    # without particle velocities the vertex velocities are zeros: made here, not copied
    world, normals, velocities, faces, bad = to_host(
        wp, [world, normals, velocities if with_v else None, faces, bad], pinned=pinned
    )
    if velocities is None:  # untouched pages: zeros_like would write every page
        velocities = np.zeros(world.shape, normals.dtype)
    f = faces.reshape(-1, 3)
    if (f.size and f.min() < 0) if on_host else bad[0] > 0:
        drop = (f < 0).any(axis=1)
        log.warning("sparse marching cubes: %d triangles touched a constant tile and were dropped", int(drop.sum()))
        f = f[~drop]
    return SurfaceMesh(world, f.astype(np.int32, copy=False), normals, velocities)


def leaves_by_voxel(d, params: SurfaceParams, *, pinned: bool) -> SparseLevelSet:
    """Blocks holding a voxel inside the band; blocks wholly at -background join the inside tiles,
    wholly at +background are dropped (what OpenVDB's pruning would do). params.density adds
    the fog density of the kept blocks. The kept blocks and the inside tiles are compacted on
    the device: a host pass over the block grid (numpy's argwhere) costs more than the copy.
    d: a mpmfx.surface.sparse.DeviceSurface."""
    grid, nact = d.grid, d.bcoord.shape[0]
    keep = wp.zeros(max(nact, 1), dtype=wp.int32)  # without active blocks, one 0 to scan
    launch_nonempty(wp, kind_equals, nact, [d.kind, 2, keep])
    offsets = scan(wp, keep, inclusive=False)
    flags = wp.empty(d.bmap.size, dtype=wp.int32)
    wp.launch(inside_tiles, d.bmap.shape, inputs=[d.bmap, flags])
    ioffsets = scan(wp, flags, inclusive=False)
    totals = wp.empty(2, dtype=wp.int32)
    wp.launch(scan_totals, 1, inputs=[keep, offsets, 0, totals])
    wp.launch(scan_totals, 1, inputs=[flags, ioffsets, 1, totals])
    m, ninside = (int(c) for c in totals.numpy())
    size = m * BS**3
    out = wp.empty(max(size, 1), dtype=float)
    launch_nonempty(wp, gather_blocks, nact * BS**3, [keep, offsets, d.values, out])
    vout = fog = None
    if d.vel is not None:
        vout = wp.empty(max(size, 1), dtype=wp.vec3)
        launch_nonempty(wp, gather_blocks_vec, nact * BS**3, [keep, offsets, d.vel, vout])
    if params.density:
        fog = wp.empty(max(size, 1), dtype=float)
        launch_nonempty(wp, gather_blocks, nact * BS**3, [keep, offsets, d.w, fog])
        launch_nonempty(wp, scale_clamp01, size, [fog, 1.0 / bulk_weight(d, params)])
    inside = wp.empty(max(ninside, 1), dtype=wp.vec3i)
    wp.launch(compact_inside_tiles, d.bmap.shape, inputs=[d.bmap, flags, ioffsets, inside])
    values, velocity, density, kinds, bcoord, inside = to_host(
        wp, [out, vout, fog, d.kind, d.bcoord, inside], pinned=pinned
    )
    return _leaves(
        grid,
        kinds[:nact],
        bcoord[:nact],
        inside[:ninside],
        values[:size].reshape(m, BS, BS, BS),
        None if velocity is None else velocity[:size].reshape(m, BS, BS, BS, 3),
        None if density is None else density[:size].reshape(m, BS, BS, BS),
    )


def leaves_by_block(d, params: SurfaceParams, *, pinned: bool) -> SparseLevelSet:
    """leaves_by_voxel where the arrays already live on the host (CPU device): the kept blocks
    taken out by numpy a whole block at a time, where the voxel-per-thread gather_blocks would
    run on one core; the same leaves."""
    grid, nact = d.grid, d.bcoord.shape[0]
    kinds = d.kind.numpy()[:nact]
    keep = kinds == 2
    m = int(keep.sum())

    def kept(a, *tail):  # a copy of the kept blocks' voxels, (m, BS, BS, BS, *tail)
        return a.numpy().reshape(-1, BS, BS, BS, *tail)[:nact][keep]

    velocity = None if d.vel is None else kept(d.vel, 3)
    density = None
    if params.density:
        density = kept(d.w)
        launch_nonempty(
            wp,
            scale_clamp01,
            m * BS**3,
            [wp.array(density.reshape(-1), dtype=float, device=d.w.device, copy=False), 1.0 / bulk_weight(d, params)],
        )
    return _leaves(
        grid, kinds, d.bcoord.numpy()[:nact], np.argwhere(d.bmap.numpy() == -2), kept(d.values), velocity, density
    )


def _leaves(
    grid, kinds: np.ndarray, bcoord: np.ndarray, inside_tiles: np.ndarray, values, velocity, density
) -> SparseLevelSet:
    """The level set of the kept blocks' voxels (values, velocity, density: (m, BS, BS, BS[, 3])),
    kinds / bcoord: the active blocks' kinds and block coordinates, inside_tiles: (k, 3) the
    block coordinates of the INSIDE tiles of the block grid (C order)."""
    blocks = bcoord.astype(np.int64).reshape(-1, 3)
    inside = np.concatenate([inside_tiles.astype(np.int64).reshape(-1, 3), blocks[kinds == 1]])
    return SparseLevelSet(
        block_ijk=blocks[kinds == 2] * BS + grid.ijk0,
        values=values,
        velocity=velocity,
        inside_ijk=inside * BS + grid.ijk0,
        voxel_size=grid.voxel,
        background=grid.background,
        density=density,
    )


def bulk_weight(d, params: SurfaceParams) -> float:
    """Kernel weight sum w deep inside the material (voxel units, as w): the mean particle count
    of blocks full of particles per block volume, times the kernel's volume integral
    4 pi R^3 16/315 for (1 - s^2)^3. A block counts as full when it and its 26 neighbours all
    hold particles: surrounded, it cannot straddle the surface. (The mean over all occupied
    blocks, as dense_output uses for its tiles, also averages half-empty surface blocks and
    spray, so a body would read 1 well before its surface.) Only spray and sheets thinner than
    three blocks have no full block; the occupied mean is what is left for them."""
    counts = d.counts.numpy()
    occupied = counts > 0
    full = occupied.copy()
    for axis in range(3):  # 3x3x3 erosion, one axis at a time
        a = np.moveaxis(full, axis, 0)
        eroded = a.copy()
        eroded[1:] &= a[:-1]
        eroded[:-1] &= a[1:]
        full = np.moveaxis(eroded, 0, axis)
    per_block = float(counts[full].mean()) if full.any() else d.n / max(int(occupied.sum()), 1)
    kernel_vox = params.kernel_radius * params.particle_radius / d.grid.voxel
    return per_block / BS**3 * kernel_volume(kernel_vox)


def dense_output(d, params: SurfaceParams) -> SurfaceResult:
    """Level set, velocity and density as dense arrays over the active blocks' bounding box."""
    grid, nact, with_v = d.grid, d.bcoord.shape[0], d.vel is not None
    if not params.dense_output or nact == 0:
        ls = LevelSet(np.zeros((0, 0, 0), np.float32), grid.ijk0.copy(), grid.voxel, grid.background)
        velocity = np.zeros((0, 0, 0, 3), np.float32) if with_v else None
        return SurfaceResult(ls, SurfaceMesh.empty(), velocity, np.zeros((0, 0, 0), np.float32))
    bc = d.bcoord.numpy()
    blo, bhi = bc.min(axis=0), bc.max(axis=0)
    shape = tuple(int(s) for s in (bhi - blo + 1) * BS)
    lo = wp.vec3i(*(blo * BS).tolist())
    bt = wp.vec3i(*blo.tolist())
    dense = wp.empty(shape, dtype=float)
    wp.launch(fill_tiles, shape, inputs=[d.bmap, bt, grid.background, -grid.background, dense])
    wp.launch(densify, d.values.shape[0], inputs=[d.bcoord, d.values, lo, dense])
    volume = kernel_volume(params.kernel_radius * params.particle_radius)
    # INSIDE blocks were never evaluated: give them the mean number density of occupied blocks
    occupied = float(np.count_nonzero(d.counts.numpy()) * (BS * grid.voxel) ** 3)
    bulk_w = d.n / occupied * volume
    wd = wp.empty(shape, dtype=float)
    wp.launch(fill_tiles, shape, inputs=[d.bmap, bt, 0.0, bulk_w, wd])
    wp.launch(densify, d.values.shape[0], inputs=[d.bcoord, d.w, lo, wd])
    velocity = None
    if with_v:
        vd = wp.zeros(shape, dtype=wp.vec3)
        wp.launch(densify_vec, d.values.shape[0], inputs=[d.bcoord, d.vel, lo, vd])
        velocity = vd.numpy()
    ls = LevelSet(dense.numpy(), grid.ijk0 + blo.astype(np.int64) * BS, grid.voxel, grid.background)
    return SurfaceResult(ls, SurfaceMesh.empty(), velocity, (wd.numpy() / volume).astype(np.float32))
