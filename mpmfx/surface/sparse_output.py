"""Host copies of the sparse surfacer's result (:class:`mpmfx.surface.sparse.DeviceSurface`):
the mesh, the level set as OpenVDB-style leaves (with velocity and fog density) and the
optional dense arrays. Split from :mod:`mpmfx.surface.sparse` to keep each module small.
"""

from __future__ import annotations

import logging
import os
import threading
import weakref

import numpy as np

from mpmfx.surface.params import LevelSet, SparseLevelSet, SurfaceMesh, SurfaceParams, SurfaceResult, kernel_volume
from mpmfx.surface.sparse import BS, DeviceSurface
from mpmfx.surface.sparse import _launch as launch
from mpmfx.surface.sparse import _lines as host_path
from mpmfx.surface.sparse import _scan as scan

log = logging.getLogger(__name__)


class PinnedPool:
    """Page-locked host buffers lent to the numpy arrays of one download and taken back when
    the last of those arrays (or a view of them) is gone, for the next call's copies.

    A device-to-host copy into pageable memory goes through the driver's staging and faults
    the destination's pages in: 35-52 ms of a 10M torus call's 83-121 ms on an H200. Into
    page-locked memory it is one DMA. Allocating page-locked memory costs more than it saves,
    so the buffers are kept: a frame's download reuses the last frame's buffers once that frame's
    arrays are gone. At most `limit` bytes are held; past that a download falls back to
    pageable arrays (a caller keeping many frames' results does not pin them all)."""

    def __init__(self, limit: int):
        self.limit = limit
        self._free: list = []  # page-locked wp.arrays of uint8 not lent
        self._held = 0  # bytes of page-locked buffers, free or lent
        self._lock = threading.RLock()  # a lent array's finalizer may run inside take(), on the same thread

    def take(self, wp, nbytes: int):
        """A page-locked uint8 wp.array of at least nbytes, or None past the limit."""
        with self._lock:
            # the smallest free buffer that holds it, however big: a cap at twice the size sent the
            # 10M bench's first calls after a bigger case to new page-locked allocations (+20-40 ms)
            fits = [b for b in self._free if nbytes <= b.size]
            if fits:
                buf = min(fits, key=lambda b: b.size)
                self._free.remove(buf)
                return buf
            size = -(-nbytes * 5 // 4 // (1 << 20)) * (1 << 20)  # room to grow: frames' sizes move
            while self._free and self._held + size > self.limit:  # free buffers too small or too big
                self._held -= self._free.pop(0).size
            if self._held + size > self.limit:
                return None
            self._held += size
        try:
            return self._allocate(wp, size)
        except RuntimeError as exc:  # page-locked memory refused (a container's memlock limit): pageable from now on
            log.warning("surface download: no page-locked host memory (%s); copying to pageable memory", exc)
            with self._lock:
                self._held -= size
                self.limit = 0
            return None

    def _allocate(self, wp, size: int):
        return wp.empty(size, dtype=wp.uint8, device="cpu", pinned=True)

    def lend(self, wp, buf, shape: tuple, dtype) -> np.ndarray:
        """A numpy array of `shape` and numpy `dtype` over buf's first bytes; buf comes back to
        the pool when that array and every view of it are gone."""
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        alias = wp.array(ptr=buf.ptr, dtype=wp.uint8, shape=(max(nbytes, 1),), device="cpu")  # owns nothing
        weakref.finalize(alias, self._give_back, buf)
        return alias.numpy()[:nbytes].view(dtype).reshape(shape)

    def _give_back(self, buf) -> None:
        with self._lock:
            self._free.append(buf)


def pinned_limit() -> int:
    """Bytes the downloads may hold page-locked: an eighth of the host's memory, at most 4 GiB
    (a 10M torus at "fine" lends 174 MB a frame, and the stage's 4 writers may hold 4 frames)."""
    try:
        ram = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        ram = 8 << 30
    return min(4 << 30, ram // 8)


PINNED = PinnedPool(limit=pinned_limit())
"""The downloads' page-locked buffers (a 10M-particle frame's mesh and leaves are ~120 MB, with
velocities ~300 MB)."""


def to_host(wp, arrays: list, *, pinned: bool) -> list:
    """numpy copies of device arrays (None stays None; arrays already on the CPU are returned as
    numpy views), every copy queued before one wait. pinned (CUDA only): into page-locked buffers
    of the PINNED pool. Else each array is copied into a buffer numpy allocated: numpy asks Linux
    for transparent huge pages on large arrays (madvise), so the copy faults in a few hundred pages
    where Warp's own host allocation (`wp.array.numpy()`) faulted 10-24 thousand. H100, 10M
    particles, "fast", the mesh and leaves, whole calls (device + copy), median of 3, two rounds:
    torus random 146 / 127 -> 97 / 96 ms, torus lattice 119 / 110 -> 93 ms, sphere lattice 75 / 87
    -> 63 / 60 ms."""
    if all(a is None or a.device.is_cpu for a in arrays):
        return [None if a is None else a.numpy() for a in arrays]
    out = []
    for a in arrays:
        if a is None:
            out.append(None)
            continue
        scalar = wp.dtype_to_numpy(getattr(a.dtype, "_wp_scalar_type_", a.dtype))
        shape = tuple(a.shape) + tuple(getattr(a.dtype, "_shape_", ()))
        nbytes = int(np.prod(shape)) * np.dtype(scalar).itemsize
        buf = PINNED.take(wp, nbytes) if pinned and nbytes else None
        host = PINNED.lend(wp, buf, shape, scalar) if buf is not None else np.empty(shape, dtype=scalar)
        wp.copy(wp.array(host, dtype=a.dtype, device="cpu", copy=False), a)
        out.append(host)
    wp.synchronize()
    return out


def download_mesh(wp, M, mesh: tuple | None, *, with_v: bool, pinned: bool) -> SurfaceMesh:
    if mesh is None:
        return SurfaceMesh.empty()
    world, normals, velocities, faces = mesh
    # a crossing on a tile face leaves a triangle a -1 corner (match_tiles should make that
    # impossible): on a GPU counted there, where a host pass over the faces cost 3 ms at 10M
    on_host = host_path(faces)
    bad = None
    if not on_host:
        bad = wp.zeros(1, dtype=wp.int32, device=faces.device)
        launch(wp, M.count_negative, faces.shape[0], [faces, bad])
    # without particle velocities the vertex velocities are zeros: made here, not copied
    world, normals, velocities, faces, bad = to_host(wp, [world, normals, velocities if with_v else None, faces, bad],
                                                     pinned=pinned)
    if velocities is None:
        velocities = np.zeros(world.shape, np.float32)  # untouched pages: zeros_like wrote 24 MB at 10M (7 ms)
    f = faces.reshape(-1, 3)
    if (f.size and f.min() < 0) if on_host else bad[0] > 0:
        drop = (f < 0).any(axis=1)
        log.warning("sparse marching cubes: %d triangles touched a constant tile and were dropped", int(drop.sum()))
        f = f[~drop]
    return SurfaceMesh(world, f.astype(np.int32, copy=False), normals, velocities)


def sparse_output(wp, M, d: DeviceSurface, params: SurfaceParams, *, pinned: bool) -> SparseLevelSet:
    """Blocks holding a voxel inside the band; blocks wholly at -background join the inside tiles,
    wholly at +background are dropped (what OpenVDB's pruning would do). params.density adds
    the fog density of the kept blocks. The kept blocks and the inside tiles are compacted on
    the device: a host pass over the block grid (numpy's argwhere) cost more than the copy."""
    grid, nact = d.grid, d.bcoord.shape[0]
    if host_path(d.values):
        return _sparse_output_host(wp, M, d, params)
    keep = wp.zeros(max(nact, 1), dtype=wp.int32)  # without active blocks, one 0 to scan
    launch(wp, M.kind_equals, nact, [d.kind, 2, keep])
    offsets = scan(wp, keep, inclusive=False)
    flags = wp.empty(d.bmap.size, dtype=wp.int32)
    wp.launch(M.inside_tiles, d.bmap.shape, inputs=[d.bmap, flags])
    ioffsets = scan(wp, flags, inclusive=False)
    totals = wp.empty(2, dtype=wp.int32)
    wp.launch(M.scan_totals, 1, inputs=[keep, offsets, 0, totals])
    wp.launch(M.scan_totals, 1, inputs=[flags, ioffsets, 1, totals])
    m, ninside = (int(c) for c in totals.numpy())
    size = m * BS**3
    out = wp.empty(max(size, 1), dtype=float)
    launch(wp, M.gather_blocks, nact * BS**3, [keep, offsets, d.values, out])
    vout = fog = None
    if d.vel is not None:
        vout = wp.empty(max(size, 1), dtype=wp.vec3)
        launch(wp, M.gather_blocks_vec, nact * BS**3, [keep, offsets, d.vel, vout])
    if params.density:
        fog = wp.empty(max(size, 1), dtype=float)
        launch(wp, M.gather_blocks, nact * BS**3, [keep, offsets, d.w, fog])
        launch(wp, M.scale_clamp01, size, [fog, 1.0 / bulk_weight(d, params)])
    inside = wp.empty(max(ninside, 1), dtype=wp.vec3i)
    wp.launch(M.compact_inside_tiles, d.bmap.shape, inputs=[d.bmap, flags, ioffsets, inside])
    values, velocity, density, kinds, bcoord, inside = to_host(wp, [out, vout, fog, d.kind, d.bcoord, inside], pinned=pinned)
    return _leaves(grid, kinds[:nact], bcoord[:nact], inside[:ninside], values[:size].reshape(m, BS, BS, BS),
                   None if velocity is None else velocity[:size].reshape(m, BS, BS, BS, 3),
                   None if density is None else density[:size].reshape(m, BS, BS, BS))


def _leaves(grid, kinds: np.ndarray, bcoord: np.ndarray, inside_tiles: np.ndarray, values, velocity, density) -> SparseLevelSet:
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


def _sparse_output_host(wp, M, d: DeviceSurface, params: SurfaceParams) -> SparseLevelSet:
    """sparse_output where the arrays already live on the host (CPU device): the kept blocks
    taken out by numpy a whole block at a time, where the voxel-per-thread gather_blocks ran
    on one core (3-6 ms at 100k "fine", a third to a half of the download); the same leaves."""
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
        launch(wp, M.scale_clamp01, m * BS**3, [wp.array(density.reshape(-1), dtype=float, device=d.w.device, copy=False),
                                                1.0 / bulk_weight(d, params)])
    return _leaves(grid, kinds, d.bcoord.numpy()[:nact], np.argwhere(d.bmap.numpy() == -2), kept(d.values), velocity, density)


def bulk_weight(d: DeviceSurface, params: SurfaceParams) -> float:
    """Kernel weight sum w deep inside the material (voxel units, as w): the mean particle count
    of blocks full of particles per block volume, times the kernel's volume integral
    4 pi R^3 16/315 for (1 - s^2)^3. A block counts as full when it and its 26 neighbours all
    hold particles: surrounded, it cannot straddle the surface. (The mean over all occupied
    blocks, as _dense_output uses for its tiles, also averages half-empty surface blocks and
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


def dense_output(wp, M, d: DeviceSurface, params: SurfaceParams) -> SurfaceResult:
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
    wp.launch(M.fill_tiles, shape, inputs=[d.bmap, bt, grid.background, -grid.background, dense])
    wp.launch(M.densify, d.values.shape[0], inputs=[d.bcoord, d.values, lo, dense])
    volume = kernel_volume(params.kernel_radius * params.particle_radius)
    # INSIDE blocks were never evaluated: give them the mean number density of occupied blocks
    occupied = float(np.count_nonzero(d.counts.numpy()) * (BS * grid.voxel) ** 3)
    bulk_w = d.n / occupied * volume
    wd = wp.empty(shape, dtype=float)
    wp.launch(M.fill_tiles, shape, inputs=[d.bmap, bt, 0.0, bulk_w, wd])
    wp.launch(M.densify, d.values.shape[0], inputs=[d.bcoord, d.w, lo, wd])
    velocity = None
    if with_v:
        vd = wp.zeros(shape, dtype=wp.vec3)
        wp.launch(M.densify_vec, d.values.shape[0], inputs=[d.bcoord, d.vel, lo, vd])
        velocity = vd.numpy()
    ls = LevelSet(dense.numpy(), grid.ijk0 + blo.astype(np.int64) * BS, grid.voxel, grid.background)
    return SurfaceResult(ls, SurfaceMesh.empty(), velocity, (wd.numpy() / volume).astype(np.float32))
