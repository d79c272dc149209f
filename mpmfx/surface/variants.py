"""The two variants of the sparse surfacer's device-specific passes, and the choice between them.

A pass that runs differently on a CPU and a GPU holds both variants side by side in its module
(:mod:`mpmfx.surface.binning`, :mod:`mpmfx.surface.classify`, :mod:`mpmfx.surface.gather`,
:mod:`mpmfx.surface.field`, :mod:`mpmfx.surface.flood`, :mod:`mpmfx.surface.components`,
:mod:`mpmfx.surface.renormalise`, :mod:`mpmfx.surface.redistance`, :mod:`mpmfx.surface.smooth`,
:mod:`mpmfx.surface.mesh`, :mod:`mpmfx.surface.output`): `*_by_voxel`, a voxel (or a line of 8)
per thread, what a GPU runs; `*_by_block`, a block of 8^3 voxels per thread, what the CPU runs
(Warp's CPU backend runs a launch's threads one after another, so there the work per voxel
counts, not the thread count). Both give every voxel the same arithmetic in the same order:
the same surface, bit for bit (tests/surface/test_line_kernels.py runs both on the CPU). The
CPU-only kernels compile in Warp modules of their own, which a GPU never loads
(:mod:`mpmfx.surface.kernel_modules`).

The table of each is built once, here; :func:`variant` picks one by device.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from mpmfx.surface import (
    binning,
    classify,
    components,
    field,
    flood,
    gather,
    mesh,
    output,
    redistance,
    renormalise,
    smooth,
)

LINE_KERNELS_ON_CPU = True  # False: the CPU runs the GPU's variant (the tests compare the two there)


@dataclass(frozen=True)
class Variant:
    """One variant of every device-specific pass (each field: that pass's function)."""

    name: str
    bin_particles: Callable
    near_blocks: Callable
    gather: Callable
    blur_weights: Callable
    project_normal: Callable
    mark_particles: Callable
    flood: Callable
    small_labels: Callable
    renormalise: Callable
    distance: Callable
    redistance: Callable
    smooth: Callable
    match_tiles: Callable
    mesh: Callable
    download_mesh: Callable
    leaves: Callable


BY_VOXEL = Variant(
    "by_voxel",
    binning.bin_particles_by_voxel,
    classify.near_blocks_by_voxel,
    gather.gather_by_voxel,
    field.blur_by_voxel,
    field.project_by_voxel,
    flood.mark_particles_by_voxel,
    flood.flood_by_voxel,
    components.labels_by_voxel,
    renormalise.renormalise_by_voxel,
    redistance.distance_by_voxel,
    redistance.redistance_by_voxel,
    smooth.smooth_by_voxel,
    mesh.match_tiles_by_voxel,
    mesh.mesh_by_voxel,
    output.mesh_by_voxel,
    output.leaves_by_voxel,
)

BY_BLOCK = Variant(
    "by_block",
    binning.bin_particles_by_block,
    classify.near_blocks_by_block,
    gather.gather_by_block,
    field.blur_by_block,
    field.project_by_block,
    flood.mark_particles_by_block,
    flood.flood_by_block,
    components.labels_by_block,
    renormalise.renormalise_by_block,
    redistance.distance_by_block,
    redistance.redistance_by_block,
    smooth.smooth_by_block,
    mesh.match_tiles_by_block,
    mesh.mesh_by_block,
    output.mesh_by_block,
    output.leaves_by_block,
)


def variant(device) -> Variant:
    """The variant for a Warp device: a block per thread on the CPU (unless LINE_KERNELS_ON_CPU
    is off), a voxel per thread on a GPU."""
    return BY_BLOCK if LINE_KERNELS_ON_CPU and device.is_cpu else BY_VOXEL
