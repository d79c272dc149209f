"""Dense reference surfacer (test-only): the same Zhu-Bridson field as the product's sparse
surfacer (mpmfx.surface.sparse), evaluated on every voxel of the particles' bounding box by
scattering from particles, or a union of spheres (`spheres=True`). The tests compare the
sparse surfacer against it; the product never runs it.

Stages (each a Warp kernel launch over a dense grid covering the particles' bounding box
plus the kernel support; the grid is aligned to multiples of the voxel size):

1. field: Zhu-Bridson phi = |x - xbar| - r projected on the normal (or a union of spheres),
   in voxel units;
2. bubbles: outside voxels that no path from the grid boundary reaches are voids left by
   irregular sampling; they become inside (flood fill by repeated line sweeps);
   The normal that x - xbar is projected on is the gradient of the weight field blurred to
   normal_radius x the kernel (as the sparse surfacer);
3. dilate; renormalise to a distance (the mean of phi / |grad phi| and that renormalised once
   more, straight to second order, as the sparse surfacer), kept next to the crossing and
   redistanced (|grad phi| = 1) over the rest of the band; smooth (`smooth_iters` steps of the
   level set's mean-curvature flow, moving the surface at most SMOOTH_LIMIT r inward); fill
   bubbles the smoothing sealed;
4. specks: inside components holding fewer than `min_feature_particles` particles go;
5. renormalise to world-unit signed distance, clipped to the narrow band;
6. marching cubes (warp.geometry) of the zero level; normals and velocities at vertices.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from mpmfx.surface.grid import NORMAL_STEP, smooth_reach
from mpmfx.surface.params import LevelSet, SurfaceMesh, SurfaceParams, SurfaceResult, kernel_volume
from mpmfx.surface.reconstruct import check_inputs
from mpmfx.surface.smooth import FLOW_BAND, FLOW_DT
from mpmfx.surface.sparse import SMOOTH_LIMIT

log = logging.getLogger(__name__)

MAX_GRID_NODES = 1 << 28  # ~268 M voxels (~1 GB per float channel): beyond this a dense grid is a mistake
MAX_SWEEP_ROUNDS = 256
PROJECTED = 1


def surface_dense(
    x: np.ndarray, v: np.ndarray | None, params: SurfaceParams, *, spheres: bool = False, device: str | None = None
) -> SurfaceResult:
    """Reconstruct the surface of a particle cloud on a dense grid (the sparse surfacer's
    reference). x: (n, 3) float world positions (m) on the host, n > 0; v: (n, 3) m/s or None.
    spheres: a union of spheres of radius r instead of Zhu-Bridson. SurfaceParams.density
    (the fog leaves) is the sparse surfacer's alone: ValueError naming the field."""
    import warp as wp

    from tests.surface import dense_kernels as K

    if params.density:
        raise ValueError(
            "SurfaceParams.density: the fog density comes from the sparse surfacer "
            "(mpmfx.surface.surface_particles); use it, or density=False"
        )
    wp.init()
    x, v = check_inputs(x, v)
    dev = wp.get_device(device)
    timings: dict[str, float] = {}
    grid = _Grid.fit(x, params, spheres=spheres)
    with wp.ScopedDevice(dev):
        t0 = time.perf_counter()
        g = wp.array(((x - grid.origin) / grid.voxel).astype(np.float32), dtype=wp.vec3)
        phi, w, vel = _raw_field(wp, K, g, v, params, grid, spheres=spheres)
        timings["field"] = _lap(wp, t0)
        _fill_bubbles(wp, K, phi, inside_value=-grid.r_vox)
        timings["bubbles"] = _lap(wp, t0)
        if params.dilate != 0.0:
            wp.launch(K.add_float, phi.shape, inputs=[phi, -params.dilate / grid.voxel])
        # Blur a distance-like field, not the raw one: the raw Zhu-Bridson profile is convex
        # across the surface, and blurring a convex profile moves flat faces inward (0.04 h
        # per pass, measured on a box); a linear profile blurs without moving.
        distance = wp.empty_like(phi)
        wide = float(params.band_voxels + smooth_reach(params) + 2)
        wp.launch(K.renormalise, phi.shape, inputs=[phi, 1.0, wide, distance])
        again = wp.empty_like(phi)
        wp.launch(K.renormalise, phi.shape, inputs=[distance, 1.0, wide, again])
        wp.launch(K.average_into, phi.shape, inputs=[distance, again])
        distance = wp.array(_redistance(distance.numpy(), wide), dtype=float)
        phi = _smooth(wp, K, wp.clone(distance), params.smooth_iters)
        if (
            params.smooth_iters > 0
        ):  # at most SMOOTH_LIMIT r inward, as the sparse surfacer on bodies without edges (its
            # edges' limit, mpmfx.surface.edges, is not modelled here: the cases compared have none)
            phi = wp.array(np.minimum(phi.numpy(), distance.numpy() + SMOOTH_LIMIT * grid.r_vox), dtype=float)
        timings["smooth"] = _lap(wp, t0)
        if params.smooth_iters > 0:
            # smoothing closes thin outside tunnels, sealing pockets they joined to the outside
            _fill_bubbles(wp, K, phi, inside_value=-wide)
        if params.min_feature_particles > 0:
            _remove_specks(wp, K, phi, g, params.min_feature_particles, far_value=wide)
        timings["specks"] = _lap(wp, t0)
        values = wp.empty_like(phi)
        wp.launch(K.renormalise, phi.shape, inputs=[phi, grid.voxel, grid.background, values])
        mesh = _extract_mesh(wp, K, values, vel, grid)
        timings["mesh"] = _lap(wp, t0)
        level_set = LevelSet(values.numpy(), grid.ijk0.copy(), grid.voxel, grid.background)
        velocity = vel.numpy() if vel is not None else None
        density = _density(w, params) if w is not None else None
    log.debug("surface_particles n=%d grid=%s timings=%s", x.shape[0], phi.shape, timings)
    return SurfaceResult(level_set, mesh, velocity, density, stats=timings)


class _Grid:
    """Dense voxel grid covering the particles, aligned to multiples of the voxel size."""

    def __init__(self, ijk0: np.ndarray, shape: tuple[int, int, int], params: SurfaceParams):
        self.voxel = params.resolved_voxel_size
        self.ijk0 = ijk0.astype(np.int64)
        self.shape = shape
        self.origin = self.ijk0.astype(np.float64) * self.voxel
        self.r_vox = params.particle_radius * params.radius_scale / self.voxel
        self.kernel_vox = params.kernel_radius * params.particle_radius / self.voxel
        self.background = params.band_voxels * self.voxel
        added = (params.normal_radius**2 - 1.0) * 0.0909 * self.kernel_vox**2  # as mpmfx.surface.sparse
        self.normal_passes = int(round(added / (0.5 * NORMAL_STEP**2)))
        # the raw field's value where no particle reaches: beyond anything near the surface
        self.far_vox = max(self.kernel_vox, self.r_vox + params.band_voxels + 1.0)

    @classmethod
    def fit(cls, x: np.ndarray, params: SurfaceParams, *, spheres: bool) -> _Grid:
        voxel = params.resolved_voxel_size
        r_vox = params.particle_radius * params.radius_scale / voxel
        support = params.kernel_radius * params.particle_radius / voxel
        if spheres:
            support = r_vox + params.band_voxels + 1.0
        reach = max(support, r_vox + max(params.dilate, 0.0) / voxel + params.band_voxels)
        # + the smoothing's reach (grid.smooth_reach); +2 keeps an outside ring
        pad = int(math.ceil(reach)) + smooth_reach(params) + 2
        lo = np.floor(x.min(axis=0).astype(np.float64) / voxel).astype(np.int64) - pad
        hi = np.ceil(x.max(axis=0).astype(np.float64) / voxel).astype(np.int64) + pad
        shape = tuple(int(s) for s in (hi - lo + 1))
        nodes = math.prod(shape)
        if nodes > MAX_GRID_NODES:
            raise ValueError(
                f"SurfaceParams.voxel_size: a dense grid of {shape[0]}x{shape[1]}x{shape[2]} voxels "
                f"({nodes / 1e6:.0f} M) would cover these particles; raise voxel_size (now {voxel:g} m) "
                "or drop far-flung particles before surfacing"
            )
        return cls(lo, shape, params)


def _lap(wp, t0: float) -> float:
    wp.synchronize()
    return round(time.perf_counter() - t0, 4)


def _raw_field(wp, K, g, v: np.ndarray | None, params: SurfaceParams, grid: _Grid, *, spheres: bool):
    """Raw implicit field (voxel units), kernel weight sum and velocity grid (or None)."""
    shape = grid.shape
    if spheres:
        phi = wp.full(shape, grid.far_vox, dtype=float)
        reach = grid.far_vox
        wp.launch(K.splat_spheres, g.shape[0], inputs=[g, grid.r_vox, reach, phi])
        return phi, None, None
    with_v = v is not None
    w = wp.zeros(shape, dtype=float)
    gw = wp.zeros(shape, dtype=wp.vec3)
    vw = wp.zeros(shape if with_v else (1, 1, 1), dtype=wp.vec3)
    va = wp.array(v if with_v else np.zeros((1, 3), np.float32), dtype=wp.vec3)
    wp.launch(K.splat_zhu_bridson, g.shape[0], inputs=[g, va, int(with_v), grid.kernel_vox, w, gw, vw])
    phi = wp.empty(shape, dtype=float)
    wn = w
    if grid.normal_passes > 0:  # the weights blurred to a wider kernel, for the normal
        wn, tmp = wp.clone(w), wp.empty_like(w)
        for _ in range(grid.normal_passes):
            for axis in range(3):
                wp.launch(K.blur_axis_step, shape, inputs=[wn, axis, NORMAL_STEP, tmp])
                wn, tmp = tmp, wn
    wp.launch(K.zhu_bridson_phi, shape, inputs=[w, wn, gw, grid.r_vox, grid.far_vox, PROJECTED, phi])
    del gw
    vel = None
    if with_v:
        vel = wp.empty(shape, dtype=wp.vec3)
        wp.launch(K.normalise_velocity, shape, inputs=[w, vw, vel])
    return phi, w, vel


def _sweep_until_stable(wp, K, labels) -> int:
    """Run +-x, +-y, +-z label sweeps until no label changes; returns the rounds used."""
    changed = wp.zeros(1, dtype=wp.int32)
    n = labels.shape
    for rounds in range(1, MAX_SWEEP_ROUNDS + 1):
        changed.zero_()
        for axis in range(3):
            others = tuple(n[a] for a in range(3) if a != axis)
            for rev in (0, 1):
                wp.launch(K.sweep_labels, others, inputs=[labels, axis, rev, changed])
        if int(changed.numpy()[0]) == 0:
            return rounds
    log.warning("label sweeps did not settle in %d rounds; some voids may remain", MAX_SWEEP_ROUNDS)
    return MAX_SWEEP_ROUNDS


def _fill_bubbles(wp, K, phi, *, inside_value: float) -> None:
    """Make outside voxels unreachable from the grid boundary inside (interior voids)."""
    labels = wp.empty(phi.shape, dtype=wp.int32)
    wp.launch(K.init_outside_labels, phi.shape, inputs=[phi, labels])
    _sweep_until_stable(wp, K, labels)
    wp.launch(K.fill_unreached, phi.shape, inputs=[phi, labels, inside_value])


def _redistance(d: np.ndarray, clip: float) -> np.ndarray:
    """numpy version of the sparse surfacer's redistancing (mpmfx.surface.redistance):
    voxels next to a sign change keep |d| capped at the axis-interpolated distance to it, the
    rest of the band follows from Jacobi sweeps of |grad d| = 1; values in voxels, +-clip."""
    pos = d > 0
    near = np.ones_like(d)
    cross = np.zeros(d.shape, bool)
    for axis in range(3):
        for shift in (1, -1):
            u = np.roll(d, shift, axis)
            edge = [slice(None)] * 3
            edge[axis] = 0 if shift == 1 else -1
            u[tuple(edge)] = d[tuple(edge)]  # no neighbour beyond the grid: no crossing
            c = (u > 0) != pos
            cross |= c
            near = np.where(c, np.minimum(near, np.abs(d) / np.maximum(np.abs(d) + np.abs(u), 1e-12)), near)
    a = np.where(cross, np.minimum(np.abs(d), near), clip).astype(np.float32)
    for _ in range(int(math.ceil(clip)) + 1):
        m = []
        for axis in range(3):
            p = np.pad(a, [(1, 1) if i == axis else (0, 0) for i in range(3)], constant_values=clip)
            lo = p[tuple(slice(0, -2) if i == axis else slice(None) for i in range(3))]
            hi = p[tuple(slice(2, None) if i == axis else slice(None) for i in range(3))]
            m.append(np.minimum(lo, hi))
        a0, a1, a2 = np.sort(np.stack(m), axis=0)
        u = a0 + 1.0
        two = 0.5 * (a0 + a1 + np.sqrt(np.maximum(2.0 - (a0 - a1) ** 2, 0.0)))
        s3 = a0 + a1 + a2
        three = (s3 + np.sqrt(np.maximum(s3 * s3 - 3.0 * (a0 * a0 + a1 * a1 + a2 * a2 - 1.0), 0.0))) / 3.0
        u = np.where(u > a1, np.where(two > a2, three, two), u)
        a = np.where(cross, a, np.minimum(np.minimum(u, a), clip)).astype(np.float32)
    return np.where(pos, a, -a).astype(np.float32)


def _smooth(wp, K, phi, iters: int):
    tmp = wp.empty_like(phi)
    for _ in range(iters):
        wp.launch(K.curvature_flow, phi.shape, inputs=[phi, FLOW_DT, FLOW_BAND, tmp])
        phi, tmp = tmp, phi
    return phi


def _remove_specks(wp, K, phi, g, min_count: int, *, far_value: float) -> None:
    """Inside components (6-connected voxels) holding < min_count particles become outside."""
    labels = wp.empty(phi.shape, dtype=wp.int32)
    wp.launch(K.init_inside_labels, phi.shape, inputs=[phi, labels])
    _sweep_until_stable(wp, K, labels)
    plabels = wp.empty(g.shape[0], dtype=wp.int32)
    wp.launch(K.particle_labels, g.shape[0], inputs=[g, labels, plabels])
    counts = wp.zeros(math.prod(phi.shape), dtype=wp.int32)
    wp.launch(K.count_particles, g.shape[0], inputs=[plabels, counts])
    wp.launch(K.remove_small, phi.shape, inputs=[labels, counts, min_count, far_value, phi])


def _extract_mesh(wp, K, values, vel, grid: _Grid) -> SurfaceMesh:
    from warp.geometry import IsoSurfaceMarchingCubes

    lower = wp.vec3(*grid.origin.astype(np.float32))
    upper = wp.vec3(*(grid.origin + (np.array(grid.shape) - 1) * grid.voxel).astype(np.float32))
    verts, tris = IsoSurfaceMarchingCubes.extract(values, 0.0, lower=lower, upper=upper)
    m = verts.shape[0]
    if m == 0:
        return SurfaceMesh.empty()
    normals = wp.empty(m, dtype=wp.vec3)
    velocities = wp.empty(m, dtype=wp.vec3)
    vel_arg = vel if vel is not None else wp.zeros((2, 2, 2), dtype=wp.vec3)
    wp.launch(
        K.sample_vertices,
        m,
        inputs=[verts, lower, 1.0 / grid.voxel, values, vel_arg, int(vel is not None), normals, velocities],
    )
    # warp's tables wind triangles counter-clockwise seen from the side where field > threshold,
    # which is our outside: faces already point outward (checked by the enclosed-volume sign).
    faces = tris.numpy().reshape(-1, 3).astype(np.int32)
    return SurfaceMesh(verts.numpy().astype(np.float32), faces, normals.numpy(), velocities.numpy())


def _density(w, params: SurfaceParams) -> np.ndarray:
    """Number density (particles / m^3) = sum of kernel weights / integral of the kernel."""
    return (w.numpy() / kernel_volume(params.kernel_radius * params.particle_radius)).astype(np.float32)
