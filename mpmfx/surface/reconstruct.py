"""Particles -> narrow-band level set -> triangle mesh, on any Warp device: the entry point.

Checks the inputs and runs the sparse (8^3 block) surfacer, :mod:`mpmfx.surface.sparse`, whose
work follows the surface area rather than the bounding-box volume. (The dense reference that
the tests compare it against lives in tests/surface/dense_reference.py.)
"""

from __future__ import annotations

import numpy as np
import warp as wp

from mpmfx.surface.params import LevelSet, SparseLevelSet, SurfaceMesh, SurfaceParams, SurfaceResult
from mpmfx.surface.sparse import surface_sparse


def surface_particles(
    x: np.ndarray, v: np.ndarray | None, params: SurfaceParams, *, device: str | None = None
) -> SurfaceResult:
    """Reconstruct the surface of a particle cloud.

    x: (n, 3) float world positions (m); v: (n, 3) float world velocities (m/s) or None.
    Either may also be a wp.array of wp.vec3 already on a device (the surfacer then runs
    there without uploading them). Non-finite positions are a ValueError, non-finite
    velocities read as 0; both are found on the device (a host pass costs more than the surfacing).
    device: Warp device ("cpu", "cuda:0"); None -> Warp's default device (ignored for device
    arrays: they run where they are).
    Returns a :class:`SurfaceResult` (its `stats` hold the stage timings); n = 0 gives an
    empty level set and mesh.
    """
    wp.init()
    on_device = isinstance(x, wp.array)
    x, v = check_device_inputs(wp, x, v) if on_device else check_inputs(x, v)
    if x.shape[0] == 0:
        return empty_result(params, with_v=v is not None)
    with wp.ScopedDevice(x.device if on_device else wp.get_device(device)):
        return surface_sparse(x, v, params)


def check_inputs(x: np.ndarray, v: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """Host inputs as arrays; ValueError naming the fix for a bad shape. (Values are checked on
    the device: binning.particle_bounds, binning.sorted_velocity.)"""
    x = np.asarray(x)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"surface_particles: x must have shape (n, 3), got {x.shape}")
    if v is not None:
        v = np.asarray(v)
        if v.shape != x.shape:
            raise ValueError(f"surface_particles: v must have the shape of x {x.shape}, got {v.shape}")
    return x, v


def check_device_inputs(wp, x, v):
    if x.dtype != wp.vec3 or x.ndim != 1:
        raise ValueError(
            f"surface_particles: a device x must be a 1-D wp.array of wp.vec3, got {x.dtype} ndim {x.ndim}"
        )
    if v is not None and (
        not isinstance(v, wp.array) or v.dtype != wp.vec3 or v.shape != x.shape or v.device != x.device
    ):
        raise ValueError(
            "surface_particles: with a device x, v must be a wp.array of wp.vec3 of the same length and device"
        )
    return x, v


def empty_result(params: SurfaceParams, *, with_v: bool) -> SurfaceResult:
    """The result for no particles: no mesh, no leaves (as a sparse run of an empty frame gives)."""
    voxel = params.resolved_voxel_size
    background = params.band_voxels * voxel
    level_set = LevelSet(np.zeros((0, 0, 0), np.float32), np.zeros(3, np.int64), voxel, background)
    velocity = np.zeros((0, 0, 0, 3), np.float32) if with_v else None
    blocks = np.zeros((0, 8, 8, 8), np.float32)
    sparse = SparseLevelSet(
        np.zeros((0, 3), np.int64),
        blocks,
        np.zeros((0, 8, 8, 8, 3), np.float32) if with_v else None,
        np.zeros((0, 3), np.int64),
        voxel,
        background,
        blocks.copy() if params.density else None,
    )
    return SurfaceResult(level_set, SurfaceMesh.empty(), velocity, np.zeros((0, 0, 0), np.float32), sparse)
