"""Phase 4 — G2P: gather v and C, advance F (or J), return mapping, advect (guide §3).

Reads the current particle buffers and writes the next ones, so a substep the stepper
rejects leaves the current state untouched. Also reduces the per-substep statistics the
stepper needs (max speed, hardening, J range) and counts what makes a substep invalid.
"""

from __future__ import annotations

import functools

import warp as wp

from .constitutive import (
    MODE_SAND,
    MODE_SNOW,
    MODE_WATER,
    MaterialParams,
    bspline_weights,
    hardening_factor,
    sand_return_map,
    snow_return_map,
    unpack_f,
)
from .state import SceneFlags

# stats[] (float32) and counts[] (int32) slots, read by the stepper in solver.py
STAT_MAX_SPEED, STAT_MAX_HARDENING, STAT_WATER_J_MIN, STAT_J_MIN, STAT_J_MAX = range(5)
COUNT_NONFINITE, COUNT_TOO_FAR, COUNT_LOST, COUNT_GRID_NONFINITE, COUNT_PER_MATERIAL = range(5)
N_STATS = 5


@wp.struct
class G2PParams:
    """dt: s; inv_dx: 1/domain; affine_keep: 1 - drag*dt, the APIC -> PIC blend of C;
    lo, hi: allowed particle coordinate range, domain units; remove: 1 to deactivate
    particles that leave [lo, hi] instead of clamping them."""

    dt: float
    inv_dx: float
    affine_keep: float
    lo: float
    hi: float
    remove: int


@functools.lru_cache(maxsize=None)
def make_g2p(flags: SceneFlags):
    """G2P kernel specialised for the scene's materials (see p2g.make_p2g)."""
    has_solid = flags.solid
    has_water = flags.water
    has_snow = flags.snow
    has_sand = flags.sand

    @wp.kernel(enable_backward=False, module=flags.key)
    def g2p(
        gp: G2PParams,
        grid_v: wp.array3d(dtype=wp.vec3),
        materials: wp.array(dtype=MaterialParams),
        material: wp.array(dtype=wp.int32),
        x: wp.array(dtype=wp.vec3),
        v: wp.array(dtype=wp.vec3),
        C: wp.array(dtype=wp.mat33),
        F: wp.array(dtype=wp.mat33),
        J: wp.array(dtype=float),
        Jp: wp.array(dtype=float),
        alive: wp.array(dtype=wp.int32),
        x_out: wp.array(dtype=wp.vec3),
        v_out: wp.array(dtype=wp.vec3),
        C_out: wp.array(dtype=wp.mat33),
        F_out: wp.array(dtype=wp.mat33),
        J_out: wp.array(dtype=float),
        Jp_out: wp.array(dtype=float),
        alive_out: wp.array(dtype=wp.int32),
        stats: wp.array(dtype=float),
        counts: wp.array(dtype=wp.int32),
    ):
        p = wp.tid()
        # carry everything over first; the branches below overwrite what changes
        x_out[p] = x[p]
        v_out[p] = v[p]
        C_out[p] = C[p]
        Jp_out[p] = Jp[p]
        alive_out[p] = alive[p]
        if wp.static(has_solid):
            F_out[p] = F[p]
        if wp.static(has_water):
            J_out[p] = J[p]
        if alive[p] == 0:
            return
        dx = 1.0 / gp.inv_dx
        xg = x[p] * gp.inv_dx
        bi = int(wp.floor(xg[0] - 0.5))
        bj = int(wp.floor(xg[1] - 0.5))
        bk = int(wp.floor(xg[2] - 0.5))
        fx = xg - wp.vec3(float(bi), float(bj), float(bk))
        W = bspline_weights(fx)  # once per particle per transfer
        v_new = wp.vec3(0.0)
        B = wp.mat33(0.0)
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    w = W[i, 0] * W[j, 1] * W[k, 2]
                    g = grid_v[bi + i, bj + j, bk + k]
                    dpos = (wp.vec3(float(i), float(j), float(k)) - fx) * dx
                    v_new += w * g
                    B += w * wp.outer(g, dpos)
        # APIC/MLS: C = B D^-1 with D^-1 = 4/dx^2; drag blends it toward PIC at a rate
        C_new = (4.0 * gp.inv_dx * gp.inv_dx * gp.affine_keep) * B
        mid = material[p]
        mat = materials[mid]
        j_now = float(1.0)
        bad = int(0)
        if wp.static(has_solid):
            if mat.mode == MODE_SNOW or mat.mode == MODE_SAND:
                # F^{n+1} = (I + dt C) F^n, then project onto the yield surface
                Ft = (wp.identity(n=3, dtype=float) + gp.dt * C_new) * F[p]
                r = wp.mat44(0.0)
                if wp.static(has_snow):
                    if mat.mode == MODE_SNOW:
                        r = snow_return_map(mat, Ft, Jp[p])
                        wp.atomic_max(stats, STAT_MAX_HARDENING, hardening_factor(mat, r[3, 3]))
                if wp.static(has_sand):
                    if mat.mode == MODE_SAND:
                        r = sand_return_map(mat, Ft, Jp[p])
                Fn = unpack_f(r)
                F_out[p] = Fn
                Jp_out[p] = r[3, 3]
                j_now = wp.determinant(Fn)
                if not (wp.isfinite(Fn) and wp.isfinite(r[3, 3])):
                    bad = 1
        if wp.static(has_water):
            if mat.mode == MODE_WATER:
                # water keeps only its volume ratio: J^{n+1} = det(I + dt C) J^n
                j_now = J[p] * wp.determinant(wp.identity(n=3, dtype=float) + gp.dt * C_new)
                if mat.clamp_pressure != 0:
                    # no tension: a separating splash must not remember its expansion, or
                    # it lands fluffy and stress-free until squeezed back to J = 1
                    j_now = wp.min(j_now, 1.0)
                J_out[p] = j_now
                wp.atomic_min(stats, STAT_WATER_J_MIN, j_now)
        x_new = x[p] + gp.dt * v_new
        speed = wp.length(v_new)
        if not (wp.isfinite(x_new) and wp.isfinite(C_new) and wp.isfinite(j_now)):
            bad = 1
        if bad != 0:
            wp.atomic_add(counts, COUNT_NONFINITE, 1)
            wp.atomic_add(counts, COUNT_PER_MATERIAL + mid, 1)
            return
        if gp.dt * speed > dx:
            # more than a cell in one substep: the stencil never saw where it lands
            wp.atomic_add(counts, COUNT_TOO_FAR, 1)
            wp.atomic_add(counts, COUNT_PER_MATERIAL + mid, 1)
        wp.atomic_max(stats, STAT_MAX_SPEED, speed)
        wp.atomic_min(stats, STAT_J_MIN, j_now)
        wp.atomic_max(stats, STAT_J_MAX, j_now)
        inside = x_new[0] >= gp.lo and x_new[0] <= gp.hi and x_new[1] >= gp.lo
        inside = inside and x_new[1] <= gp.hi and x_new[2] >= gp.lo and x_new[2] <= gp.hi
        if not inside:
            if gp.remove != 0:
                alive_out[p] = 0
                wp.atomic_add(counts, COUNT_LOST, 1)
            else:
                x_new = wp.vec3(
                    wp.clamp(x_new[0], gp.lo, gp.hi), wp.clamp(x_new[1], gp.lo, gp.hi), wp.clamp(x_new[2], gp.lo, gp.hi)
                )
        x_out[p] = x_new
        v_out[p] = v_new
        C_out[p] = C_new
    return g2p
