"""The sparse surfacer's block grid: its bounds, reaches and the rule for INSIDE blocks (no Warp)."""

from __future__ import annotations

import math

import numpy as np

from mpmfx.surface.params import PARTICLE_RADIUS_PER_SPACING, GridTooLarge, SurfaceParams

BS = 8  # block edge in voxels (an OpenVDB leaf)
MAX_BLOCKS = 1 << 26  # block-grid cells: 2^26 blocks = 2^35 voxels of bounding box (8x as many int32 gather cells)
NORMAL_STEP = 2  # voxels between the taps of the weight blur (the weights are smooth at 1 voxel)
FLOW_REACH = 4  # voxels from the zero level that the smoothing reads: its band (smooth.FLOW_BAND) and its stencil
ANISO_MAX_STRETCH = 1.6  # longest axis / the isotropic kernel radius (bounds the gather's reach)
MAX_DENSE_FILL = 0.5  # of a full block's particles: the most the INSIDE rule asks of a neighbour (dense_rule)


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
        # final renormalise's differences across the band (the Eikonal sweeps converge them)
        self.read_vox = float(max(smooth_reach(params), params.band_voxels + 1))
        # the active blocks: those with a voxel within reach_vox of a particle. They must hold
        # what is read around the surface: `read` voxels around the zero level, which the
        # smoothing moves outward by a voxel or so (s = read + 1 from the raw field's inside,
        # phi <= dilation, r' = r + dilation voxels). An inside point x of the Zhu-Bridson field
        # has xbar, the weighted mean of the particles within the gather's reach R, within r'
        # of x, so along any direction u some particle p has (p - x).u >= -r', and x + s u lies
        # within sqrt(R^2 + s^2 + 2 s r') of p: the reach. It covers a surface bridged between
        # sparse particles (spray: the raw inside up to R from them) as well as a body's. The
        # projection on the wide normal bounds only the normal part of x - xbar; that no voxel
        # within `read` of the raw inside lies outside the active blocks is checked by
        # tests/surface/test_sparse.py (spray and a random box).
        dilation = max(params.dilate, 0.0) / self.voxel
        s = self.read_vox + 1.0
        self.reach_vox = math.sqrt(self.gather_vox**2 + s * s + 2.0 * s * (self.r_vox + dilation))
        self.reach_blocks = int(math.ceil(self.reach_vox / BS))
        self.dense_reach, self.dense_min, self.inside_depth = dense_rule(self, params)
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


def dense_rule(grid: SparseGrid, params: SurfaceParams) -> tuple[int, int, float]:
    """(dense_reach blocks, dense_min particles, depth voxels): a block is INSIDE when every
    block within dense_reach holds at least dense_min particles (classify.classify_blocks);
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
    A looser rule would let blocks a few voxels under a face be INSIDE, and the smoothing, reading
    -wide there, would push patches of the face outward wherever the face cut its block so."""
    # the kernel's reach across the surface is the round kernel's (anisotropic kernels are
    # short across it, long only along it)
    depth = max(grid.kernel_vox, float(smooth_reach(params))) - 1.0
    reach = 1 + max(0, int(math.ceil((depth - MAX_DENSE_FILL * BS) / BS)))
    fill = min(max((depth - (reach - 1) * BS) / BS, 1.0 / BS), MAX_DENSE_FILL)
    spacing = params.particle_radius / PARTICLE_RADIUS_PER_SPACING
    full = (BS * grid.voxel / spacing) ** 3
    return reach, max(1, int(math.ceil(fill * full))), (reach - 1 + fill) * BS
