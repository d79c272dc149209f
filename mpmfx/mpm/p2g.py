"""Phase 2 — P2G: scatter mass, momentum and the MLS stress onto the grid (docs/physics.md, "The method").

Each particle writes into its 3x3x3 node block with atomic adds. MLS-MPM fuses the stress
into the affine term:

    affine = -dt * V0 * (4 / dx^2) * tau + m * C        tau = P F^T (Kirchhoff stress)
    node momentum += w * (m v + affine @ dpos),  node mass += w * m

Deterministic mode: float atomics are not associative, so the order in which
GPU threads land on a node changes the sum. With `deterministic`, every contribution is
rounded to a fixed-point int64 and added with integer atomics (associative), so replays
are bit-identical on the same machine. Quanta are powers of two so scaling is exact:
    mass quantum  = 2^-32 * m_ref        (m_ref: mean particle mass)
    momentum quantum = 2^-32 * m_ref * 1 domain/s
Range: |node sum| < 2^63 quanta, i.e. node mass < 2^31 m_ref and node momentum
< 2^31 m_ref domain/s; a node would need 2^31 particles at 1 domain/s, or a handful at
~1e8 domain/s (which the CFL step rejects long before), to overflow. Resolution: the
rounding error per contribution is <= half a quantum, ~1e-10 of one particle's m * (1
domain/s), below float32 resolution for speeds above ~1e-3 domain/s.

Multi-field contact (opt-in): every body field has its own block of nodes; the grid's
first axis is field * nodes + i. Each particle also scatters its mass gradient
m * grad(w) (in 1/cell units) so the grid update can find the contact normal.

FLIP blend (SceneFlags.flip > 0): each particle also scatters its momentum without the
stress, w * m (v + C dpos), into `grid_mv0` (fixed point: channels from
SceneFlags.flip_channel), so G2P can rebuild the grid's velocity before the update.
"""

from __future__ import annotations

import functools

import warp as wp

from .constitutive import (
    MODE_SAND,
    MODE_SNOW,
    MODE_WATER,
    MaterialParams,
    bspline_gradients,
    bspline_weights,
    from_sym,
    tait_pressure,
    vec6,
)
from .state import SceneFlags, load_m33
from .stepper import SubstepDev

FIXED_POINT_BITS = 32  # see module docstring


@wp.struct
class P2GParams:
    """inv_dx: 1/domain; dt: s; nodes: grid nodes per axis (grid_n + 1); deterministic: 1
    for fixed-point accumulation; q_mass_inv, q_mom_inv: 1 / fixed-point quanta."""

    inv_dx: float
    dt: float
    nodes: int
    deterministic: int
    q_mass_inv: float
    q_mom_inv: float


@wp.func
def to_fixed(value: float, quantum_inv: float) -> wp.int64:
    """value -> nearest multiple of the quantum, as an integer (quantum_inv a power of 2)."""
    return wp.int64(wp.round(value * quantum_inv))


@functools.lru_cache(maxsize=None)
def make_particle_affine(flags: SceneFlags):
    """The MLS affine term of one particle, specialised like make_p2g:
    -dt V0 (4 / dx^2) tau + m C, with tau the Kirchhoff stress of its mode: a solid's as
    the last G2P stored it (g2p.py), water's from J. Shared by the reference P2G and the
    brick one (p2g_brick.py) so both scatter the same numbers."""
    has_solid = flags.solid
    has_water = flags.water

    @wp.func
    def particle_affine(
        pp: P2GParams,
        mat: MaterialParams,
        stress: wp.array(dtype=vec6),
        J: wp.array(dtype=float),
        C: wp.array2d(dtype=wp.vec3),
        volume: wp.array(dtype=float),
        p: int,
        m: float,
    ) -> wp.mat33:
        tau = wp.mat33(0.0)
        if wp.static(has_solid):
            if mat.mode == MODE_SNOW or mat.mode == MODE_SAND:
                tau = from_sym(stress[p])
        if wp.static(has_water):
            if mat.mode == MODE_WATER:
                Jw = J[p]
                # pressure only, isotropic: tau = -p J I
                tau = wp.identity(n=3, dtype=float) * (-tait_pressure(mat, Jw) * Jw)
        inv_dx = pp.inv_dx
        # D^-1 = 4 / dx^2 for quadratic B-splines
        return (-pp.dt * volume[p] * 4.0 * inv_dx * inv_dx) * tau + m * load_m33(C, p)

    return particle_affine


@functools.lru_cache(maxsize=None)
def make_p2g(flags: SceneFlags, *, device_clock: bool = False):
    """P2G kernel specialised for the scene's materials (wp.static drops unused branches,
    so a water-only scene compiles no SVD). One kernel per scene flags, shared by solvers.
    device_clock: read dt from `sub` (the device stepper, stepper.py) and do nothing when
    the substep is inactive; otherwise `sub` is unused (the reference path)."""
    multi = flags.multi_field
    one = flags.one_material
    flip = flags.flip > 0.0
    flip_channel = flags.flip_channel
    particle_affine = make_particle_affine(flags)

    @wp.kernel(enable_backward=False, module=flags.key + ("_dev" if device_clock else ""))
    def p2g(
        pp: P2GParams,
        x: wp.array(dtype=wp.vec3),
        v: wp.array(dtype=wp.vec3),
        C: wp.array2d(dtype=wp.vec3),
        tau: wp.array(dtype=vec6),
        J: wp.array(dtype=float),
        alive: wp.array(dtype=wp.int32),
        mass: wp.array(dtype=float),
        volume: wp.array(dtype=float),
        material: wp.array(dtype=wp.int32),
        field_id: wp.array(dtype=wp.int32),
        materials: wp.array(dtype=MaterialParams),
        grid_m: wp.array3d(dtype=float),
        grid_mv: wp.array3d(dtype=wp.vec3),
        grid_normal: wp.array3d(dtype=wp.vec3),
        grid_fixed: wp.array4d(dtype=wp.int64),
        sub: wp.array(dtype=SubstepDev),
        grid_mv0: wp.array3d(dtype=wp.vec3),
    ):
        p = wp.tid()
        if wp.static(device_clock):
            if sub[0].active == 0:
                return
            pp.dt = sub[0].dt
        m = mass[p]
        if alive[p] == 0 or m == 0.0:
            return  # tracers and removed particles add nothing
        mid = int(0)  # (the only material's, where the scene has one: not read)
        if wp.static(not one):
            mid = material[p]
        affine = particle_affine(pp, materials[mid], tau, J, C, volume, p, m)
        inv_dx = pp.inv_dx
        dx = 1.0 / inv_dx
        mv = m * v[p]
        mc = wp.mat33(0.0)
        if wp.static(flip):
            mc = m * load_m33(C, p)  # the affine momentum alone (the stress is `affine`'s other term)
        xg = x[p] * inv_dx
        bi = int(wp.floor(xg[0] - 0.5))
        bj = int(wp.floor(xg[1] - 0.5))
        bk = int(wp.floor(xg[2] - 0.5))
        fx = xg - wp.vec3(float(bi), float(bj), float(bk))
        W = bspline_weights(fx)  # once per particle per transfer
        dW = bspline_gradients(fx)
        if wp.static(multi):
            bi += field_id[p] * pp.nodes  # this body's block of nodes
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    w = W[i, 0] * W[j, 1] * W[k, 2]
                    dpos = (wp.vec3(float(i), float(j), float(k)) - fx) * dx
                    mom = w * (mv + affine * dpos)
                    gm = wp.vec3(0.0)
                    if wp.static(multi):
                        # mass gradient w.r.t. the node position (d/dx_node = -d/dfx), per cell
                        gm = -m * wp.vec3(
                            dW[i, 0] * W[j, 1] * W[k, 2], W[i, 0] * dW[j, 1] * W[k, 2], W[i, 0] * W[j, 1] * dW[k, 2]
                        )
                    if pp.deterministic != 0:
                        wp.atomic_add(grid_fixed, bi + i, bj + j, bk + k, 0, to_fixed(w * m, pp.q_mass_inv))
                        for c in range(3):
                            wp.atomic_add(grid_fixed, bi + i, bj + j, bk + k, 1 + c, to_fixed(mom[c], pp.q_mom_inv))
                            if wp.static(multi):
                                wp.atomic_add(grid_fixed, bi + i, bj + j, bk + k, 4 + c, to_fixed(gm[c], pp.q_mass_inv))
                    else:
                        wp.atomic_add(grid_m, bi + i, bj + j, bk + k, w * m)
                        wp.atomic_add(grid_mv, bi + i, bj + j, bk + k, mom)
                        if wp.static(multi):
                            wp.atomic_add(grid_normal, bi + i, bj + j, bk + k, gm)
                    if wp.static(flip):
                        mom0 = w * (mv + mc * dpos)
                        if pp.deterministic != 0:
                            for c in range(3):
                                q = to_fixed(mom0[c], pp.q_mom_inv)
                                wp.atomic_add(grid_fixed, bi + i, bj + j, bk + k, wp.static(flip_channel) + c, q)
                        else:
                            wp.atomic_add(grid_mv0, bi + i, bj + j, bk + k, mom0)

    return p2g
