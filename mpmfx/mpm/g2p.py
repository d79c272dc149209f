"""Phase 4 — G2P: gather v and C, advance F (or J), return mapping, advect.

docs/physics.md, "The method".

A solid's Kirchhoff stress is computed here, from the SVD the return map already took, and
stored for the next substep's P2G: computing it in P2G from F would cost a second
SVD a particle and substep (stress of the elastic F G2P writes = stress P2G would compute).

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
    sand_plastic,
    snow_plastic,
    solid_tau,
    sym6,
    uninvert,
    vary_material,
    vec5,
    vec6,
)
from .slots import Count, Stat
from .state import SceneFlags, load_m33, store_m33
from .stepper import SubstepDev

G2P_MAX_REGISTERS = 72  # see g2p_launch_shape
G2P_BLOCK = 128  # threads a block
G2P_FAST_MATH = True  # see make_g2p


def g2p_launch_shape() -> tuple[int, int]:
    """(register cap, threads a block) of G2P, every scene: 72 registers in blocks of 128 fit 7
    blocks a multiprocessor (28 warps), where 256-thread blocks fit 3 at 80 or 72: the fastest
    shape for snow, sand and water alike, with fast math and the polar shortcut
    (constitutive.snow_plastic)."""
    return G2P_MAX_REGISTERS, G2P_BLOCK


@wp.struct
class G2PParams:
    """dt: s; inv_dx: 1/domain; affine_keep: 1 - drag*dt, the APIC -> PIC blend of C;
    lo, hi: allowed particle coordinate range, domain units; remove: 1 to deactivate
    particles that leave [lo, hi] instead of clamping them; nodes: grid nodes per axis;
    deterministic, q_mass: how P2G stored the node masses (fixed point and its quantum),
    read by water volume recovery."""

    dt: float
    inv_dx: float
    affine_keep: float
    lo: float
    hi: float
    remove: int
    nodes: int
    deterministic: int
    q_mass: float


@wp.func
def gather(grid_v: wp.array3d(dtype=wp.vec3), x: wp.vec3, inv_dx: float, field_offset: int):
    """Gather from the particle's 3x3x3 nodes: v = sum w v_i, and the APIC/MLS affine
    velocity C = (sum w v_i dpos^T) D^-1 with D^-1 = 4 / dx^2.
    field_offset: first-axis offset of the particle's velocity field (multi-field).

    Summed as sum w v_i (i, j, k)^T - v fx^T, dx and D^-1 applied once at the end: with the
    loops unrolled the node offsets are constants, so a node costs v's three adds and three to
    six for the columns whose offset is 1 or 2, where the outer product with dpos took nine
    multiply-adds and dpos three subtractions. Results move by float rounding only."""
    xg = x * inv_dx
    bi = int(wp.floor(xg[0] - 0.5))
    bj = int(wp.floor(xg[1] - 0.5))
    bk = int(wp.floor(xg[2] - 0.5))
    fx = xg - wp.vec3(float(bi), float(bj), float(bk))
    W = bspline_weights(fx)  # once per particle per transfer
    v = wp.vec3(0.0)
    # sum w v_i (dpos / dx)^T = sum w v_i (i, j, k)^T - v fx^T: the node offsets are the unrolled
    # loops' constants, so each column sums only the nodes whose offset is 1 or 2
    s0 = wp.vec3(0.0)
    s1 = wp.vec3(0.0)
    s2 = wp.vec3(0.0)
    for i in range(3):
        for j in range(3):
            wij = W[i, 0] * W[j, 1]
            for k in range(3):
                wg = (wij * W[k, 2]) * grid_v[field_offset + bi + i, bj + j, bk + k]
                v += wg
                if i == 1:
                    s0 += wg
                elif i == 2:
                    s0 += 2.0 * wg
                if j == 1:
                    s1 += wg
                elif j == 2:
                    s1 += 2.0 * wg
                if k == 1:
                    s2 += wg
                elif k == 2:
                    s2 += 2.0 * wg
    B = wp.mat33(
        s0[0] - v[0] * fx[0],
        s1[0] - v[0] * fx[1],
        s2[0] - v[0] * fx[2],
        s0[1] - v[1] * fx[0],
        s1[1] - v[1] * fx[1],
        s2[1] - v[1] * fx[2],
        s0[2] - v[2] * fx[0],
        s1[2] - v[2] * fx[1],
        s2[2] - v[2] * fx[2],
    )
    return v, (4.0 * inv_dx) * B


@wp.func
def gather_old(
    gp: G2PParams,
    grid_m: wp.array3d(dtype=float),
    grid_fixed: wp.array4d(dtype=wp.int64),
    grid_mv0: wp.array3d(dtype=wp.vec3),
    x: wp.vec3,
    field_offset: int,
    channel: int,
) -> wp.vec3:
    """The grid's velocity before the update at the particle, domain/s: sum w_i mv0_i / m_i,
    with mv0 the momentum P2G scattered without the stress (p2g.py, FLIP blend), from the
    fixed-point channels `channel`.. in deterministic mode (whose momentum quantum is the mass
    quantum, Solver._build_state), else from grid_mv0. Empty nodes add nothing."""
    xg = x * gp.inv_dx
    bi = int(wp.floor(xg[0] - 0.5))
    bj = int(wp.floor(xg[1] - 0.5))
    bk = int(wp.floor(xg[2] - 0.5))
    W = bspline_weights(xg - wp.vec3(float(bi), float(bj), float(bk)))
    bi += field_offset
    v = wp.vec3(0.0)
    for i in range(3):
        for j in range(3):
            for k in range(3):
                m = float(0.0)
                mv = wp.vec3(0.0)
                if gp.deterministic != 0:
                    m = float(grid_fixed[bi + i, bj + j, bk + k, 0]) * gp.q_mass
                    for c in range(3):
                        mv[c] = float(grid_fixed[bi + i, bj + j, bk + k, channel + c]) * gp.q_mass
                else:
                    m = grid_m[bi + i, bj + j, bk + k]
                    mv = grid_mv0[bi + i, bj + j, bk + k]
                if m > 0.0:
                    v += (W[i, 0] * W[j, 1] * W[k, 2] / m) * mv
    return v


@wp.func
def grid_density(
    gp: G2PParams,
    grid_m: wp.array3d(dtype=float),
    grid_fixed: wp.array4d(dtype=wp.int64),
    x: wp.vec3,
    field_offset: int,
):
    """Grid density at the particle, mass/domain^3: sum w_i m_i / dx^3 over its 27 nodes
    (exactly the rest density inside a uniformly sampled body at J = 1), and the smallest
    node density among them (low near a free surface). Returns (density, smallest)."""
    xg = x * gp.inv_dx
    bi = int(wp.floor(xg[0] - 0.5))
    bj = int(wp.floor(xg[1] - 0.5))
    bk = int(wp.floor(xg[2] - 0.5))
    W = bspline_weights(xg - wp.vec3(float(bi), float(bj), float(bk)))
    bi += field_offset
    rho = float(0.0)
    m_min = float(1.0e30)
    for i in range(3):
        for j in range(3):
            for k in range(3):
                m = float(0.0)
                if gp.deterministic != 0:
                    m = float(grid_fixed[bi + i, bj + j, bk + k, 0]) * gp.q_mass
                else:
                    m = grid_m[bi + i, bj + j, bk + k]
                rho += W[i, 0] * W[j, 1] * W[k, 2] * m
                m_min = wp.min(m_min, m)
    inv_vol = gp.inv_dx * gp.inv_dx * gp.inv_dx
    return rho * inv_vol, m_min * inv_vol


@wp.func
def plastic_update(mat: MaterialParams, F: wp.mat33, jp: float, C: wp.mat33, dt: float):
    """F^{n+1} = (I + dt C) F^n, mirrored out if inverted (see constitutive.uninvert), then
    the return map of the particle's mode.
    Returns (elastic F, new Jp slot, Kirchhoff stress of both (the next P2G's), det of the
    trial F: <= 0 means it was inverted)."""
    Ft = (wp.identity(n=3, dtype=float) + dt * C) * F
    jt = wp.determinant(Ft)
    if jt <= 0.0:
        Ft = uninvert(Ft)
    if mat.mode == MODE_SNOW:
        Fe, jp_new, tau = snow_plastic(mat, Ft, jp)
        return Fe, jp_new, tau, jt
    Fe, jp_new, tau = sand_plastic(mat, Ft, jp)
    return Fe, jp_new, tau, jt


@wp.func
def keep_in_domain(gp: G2PParams, x: wp.vec3, counts: wp.array(dtype=wp.int32)):
    """Clamp x into [lo, hi]^3, or (REMOVE mode) flag the particle dead. Returns (x, alive)."""
    inside = x[0] >= gp.lo and x[0] <= gp.hi and x[1] >= gp.lo
    inside = inside and x[1] <= gp.hi and x[2] >= gp.lo and x[2] <= gp.hi
    if inside:
        return x, 1
    if gp.remove != 0:
        wp.atomic_add(counts, Count.LOST, 1)
        return x, 0
    return wp.vec3(wp.clamp(x[0], gp.lo, gp.hi), wp.clamp(x[1], gp.lo, gp.hi), wp.clamp(x[2], gp.lo, gp.hi)), 1


@wp.func
def recover_volume(
    gp: G2PParams,
    mat: MaterialParams,
    grid_m: wp.array3d(dtype=float),
    grid_fixed: wp.array4d(dtype=wp.int64),
    x: wp.vec3,
    field_offset: int,
    J: float,
) -> float:
    """Water grid volume recovery (materials.Material.volume_recovery): relax J toward the
    volume ratio the grid measures, capped at 1. Only where every node of the stencil is at
    least half full: near a free surface the grid reads missing neighbours as expansion, and
    relaxing toward it takes the pressure away there, so the top layer packs and the level
    sinks, even in a still tank."""
    rho, rho_min = grid_density(gp, grid_m, grid_fixed, x, field_offset)
    if rho_min < 0.5 * mat.density:
        return J
    target = wp.min(mat.density / rho, 1.0)
    return J + (target - J) * (1.0 - wp.exp(-mat.volume_recovery_rate * gp.dt))


@functools.lru_cache(maxsize=None)
def make_g2p(flags: SceneFlags, *, device_clock: bool = False, sorting: bool = False):
    """G2P kernel specialised for the scene's materials (see p2g.make_p2g, also for device_clock).
    sorting: the variant of a substep whose brick P2G sorted, which stores each particle in its new
    slot (State: storage order; `order` is the sort's, slot -> particle), in a module of its own: the
    variant without that code keeps a register more for the rest, which makes it faster."""
    has_solid = flags.solid
    has_water = flags.water
    recovery = flags.volume_recovery
    multi = flags.multi_field
    one = flags.one_material
    varied = flags.varied
    flip = flags.flip > 0.0
    flip_share = flags.flip
    flip_channel = flags.flip_channel

    # registers capped (g2p_launch_shape): a solid's return map took the compiler to 128, which
    # leaves a multiprocessor 512 threads
    module = flags.key + "_g2p" + ("_dev" if device_clock else "") + ("_sort" if sorting else "")
    # CUDA fast math (G2P's module only; no effect on the CPU): approximate division, square
    # root, exp and log (~2 ulp) and denormals flushed. The return map's SVD divides twice in
    # each of its 12 Jacobi rotations, the sand return map takes logs and exps, so G2P is
    # faster with it. Deterministic mode still replays bit for bit; F moves by about the fast
    # mode's own run-to-run difference, and the errors of the bench's experiments section
    # against the published data do not change (lab/p2g_gpu.py compares the two on a GPU).
    wp.set_module_options({"fast_math": G2P_FAST_MATH}, module=module)

    @wp.kernel(enable_backward=False, module=module, cuda_max_registers=g2p_launch_shape()[0])
    def g2p(
        gp: G2PParams,
        grid_v: wp.array3d(dtype=wp.vec3),
        grid_m: wp.array3d(dtype=float),
        grid_fixed: wp.array4d(dtype=wp.int64),
        materials: wp.array(dtype=MaterialParams),
        material: wp.array(dtype=wp.int32),
        field_id: wp.array(dtype=wp.int32),
        x: wp.array(dtype=wp.vec3),
        v: wp.array(dtype=wp.vec3),
        C: wp.array2d(dtype=wp.vec3),
        F: wp.array2d(dtype=wp.vec3),
        J: wp.array(dtype=float),
        Jp: wp.array(dtype=float),
        alive: wp.array(dtype=wp.int32),
        tau: wp.array(dtype=vec6),
        x_out: wp.array(dtype=wp.vec3),
        v_out: wp.array(dtype=wp.vec3),
        C_out: wp.array2d(dtype=wp.vec3),
        F_out: wp.array2d(dtype=wp.vec3),
        J_out: wp.array(dtype=float),
        Jp_out: wp.array(dtype=float),
        alive_out: wp.array(dtype=wp.int32),
        tau_out: wp.array(dtype=vec6),
        stats: wp.array(dtype=float),
        counts: wp.array(dtype=wp.int32),
        sub: wp.array(dtype=SubstepDev),
        order: wp.array(dtype=wp.int32),
        mass: wp.array(dtype=float),
        volume: wp.array(dtype=float),
        body: wp.array(dtype=wp.int32),
        pid: wp.array(dtype=wp.int32),
        mass_out: wp.array(dtype=float),
        volume_out: wp.array(dtype=float),
        material_out: wp.array(dtype=wp.int32),
        body_out: wp.array(dtype=wp.int32),
        field_id_out: wp.array(dtype=wp.int32),
        pid_out: wp.array(dtype=wp.int32),
        vary: wp.array(dtype=vec5),
        grid_mv0: wp.array3d(dtype=wp.vec3),
    ):
        slot = wp.tid()
        if wp.static(device_clock):
            s = sub[0]
            if s.active == 0:
                return
            gp.dt = s.dt
            gp.affine_keep = s.affine_keep
        # the particle this thread advances, and the slot it is stored in next: the same one,
        # or (sorting: the brick P2G sorted at this substep) the sort's order, slot -> particle,
        # with the constants moved along into their other copy (state.State: storage order)
        p = slot
        if wp.static(sorting):
            p = order[slot]
            mass_out[slot] = mass[p]
            volume_out[slot] = volume[p]
            material_out[slot] = material[p]
            body_out[slot] = body[p]
            field_id_out[slot] = field_id[p]
            pid_out[slot] = pid[p]
        F_new = wp.mat33(0.0)
        tau_new = vec6(0.0)
        solid = bool(False)  # a solid's stress is stored for the next P2G
        if wp.static(has_solid):
            F_new = load_m33(F, p)
        J_new = float(1.0)
        if wp.static(has_water):
            J_new = J[p]
        jp_new = Jp[p]
        x_new = x[p]
        v_new = wp.vec3(0.0)
        C_new = wp.mat33(0.0)
        alive_new = alive[p]
        if alive_new == 0:
            # a removed particle keeps its v and C; a live one's come from the grid alone, so
            # they are not read (48 of G2P's ~220 bytes a solid particle, C a slow 36-byte load)
            v_new = v[p]
            C_new = load_m33(C, p)
            if wp.static(has_solid):
                # and its stored stress: a dormant particle's (emission.py) is what its first P2G
                # reads when it wakes, so both copies must hold it (a checkpoint saves one)
                tau_new = tau[p]
                solid = True
        else:
            # a scene of one field or one material reads neither index: 8 bytes of the 32 a
            # water particle reads here, 64 a snow one, and the material row's load no longer
            # waits on a per-particle load
            fo = int(0)
            if wp.static(multi):
                fo = field_id[p] * gp.nodes
            v_new, C_new = gather(grid_v, x[p], gp.inv_dx, fo)
            v_move = v_new  # what advects the particle: the grid's velocity
            if wp.static(flip):
                # FLIP blend (Fei et al. 2021): flip (v_p + sum w (v_i - v_i_old)) + (1 - flip) sum w v_i
                v_old = gather_old(gp, grid_m, grid_fixed, grid_mv0, x[p], fo, wp.static(flip_channel))
                v_new = v_move + wp.static(flip_share) * (v[p] - v_old)
            C_new = gp.affine_keep * C_new  # drag: blend toward PIC at a rate, not a per-substep fraction
            mid = int(0)
            if wp.static(not one):
                mid = material[p]
            mat = materials[mid]
            wave = float(1.0)  # the particle's stiffness / density factor (snow: on its hardening statistic)
            if wp.static(varied):
                f = vary[pid[p]]  # (particle order: pid, as slots move)
                mat = vary_material(mat, f)
                wave = f[4]
            j_now = float(1.0)
            finite = bool(True)
            if wp.static(has_solid):
                if mat.mode == MODE_SNOW or mat.mode == MODE_SAND:
                    solid = True
                    F_new, jp_new, tau_new, j_trial = plastic_update(mat, F_new, jp_new, C_new, gp.dt)
                    j_now = wp.determinant(F_new)
                    if j_trial <= 0.0:
                        # mirrored back out; the J stats keep the inversion so QA sees it
                        wp.atomic_add(counts, Count.INVERTED, 1)
                        j_now = j_trial
                    finite = wp.isfinite(F_new) and wp.isfinite(jp_new)
                    if mat.mode == MODE_SNOW:
                        h = hardening_factor(mat, jp_new)
                        if wp.static(varied):
                            h = h * wave
                        wp.atomic_max(stats, Stat.MAX_HARDENING, h)
            if wp.static(has_water):
                if mat.mode == MODE_WATER:
                    # water keeps only its volume ratio: J^{n+1} = det(I + dt C) J^n
                    J_new = J_new * wp.determinant(wp.identity(n=3, dtype=float) + gp.dt * C_new)
                    if wp.static(recovery):
                        if mat.volume_recovery != 0:
                            J_new = recover_volume(gp, mat, grid_m, grid_fixed, x[p], fo, J_new)
                    if mat.clamp_pressure != 0:
                        # no tension: a separating splash must not remember its expansion,
                        # or it lands fluffy and stress-free until squeezed back to J = 1
                        J_new = wp.min(J_new, 1.0)
                    j_now = J_new
                    wp.atomic_min(stats, Stat.WATER_J_MIN, J_new)
            x_new = x_new + gp.dt * v_move
            speed = wp.length(v_new)
            if wp.static(flip):
                speed = wp.max(speed, wp.length(v_move))  # the CFL's and the one-cell check's
            finite = finite and wp.isfinite(x_new) and wp.isfinite(C_new) and wp.isfinite(j_now)
            if wp.static(flip):
                finite = finite and wp.isfinite(v_new)
            if not finite:
                wp.atomic_add(counts, Count.NONFINITE, 1)
                wp.atomic_add(counts, Count.PER_MATERIAL + mid, 1)
                return  # the substep is rejected; nothing of it is committed
            if gp.dt * speed > 1.0 / gp.inv_dx:
                # more than a cell in one substep: the stencil never saw where it lands
                wp.atomic_add(counts, Count.TOO_FAR, 1)
                wp.atomic_add(counts, Count.PER_MATERIAL + mid, 1)
            wp.atomic_max(stats, Stat.MAX_SPEED, speed)
            wp.atomic_min(stats, Stat.J_MIN, j_now)
            wp.atomic_max(stats, Stat.J_MAX, j_now)
            x_new, alive_new = keep_in_domain(gp, x_new, counts)
        # each output written once (G2P is memory bound)
        x_out[slot] = x_new
        v_out[slot] = v_new
        store_m33(C_out, slot, C_new)
        Jp_out[slot] = jp_new
        alive_out[slot] = alive_new
        if wp.static(has_solid):
            store_m33(F_out, slot, F_new)
            if solid:
                tau_out[slot] = tau_new
        if wp.static(has_water):
            J_out[slot] = J_new

    return g2p


@wp.kernel(enable_backward=False)
def solid_stress(
    materials: wp.array(dtype=MaterialParams),
    material: wp.array(dtype=wp.int32),
    F: wp.array2d(dtype=wp.vec3),
    Jp: wp.array(dtype=float),
    tau: wp.array(dtype=vec6),
    vary: wp.array(dtype=vec5),
    pid: wp.array(dtype=wp.int32),
    varied: int,
):
    """tau (n,) of every snow and sand particle from its F and Jp (solid_tau), for a state
    that has no stored stress yet (a new one, or a checkpoint written before G2P stored it).
    varied: 1 to apply the particles' own factors (vary, in particle order: see State)."""
    p = wp.tid()
    mat = materials[material[p]]
    if varied != 0:
        mat = vary_material(mat, vary[pid[p]])
    if mat.mode == MODE_SNOW or mat.mode == MODE_SAND:
        tau[p] = sym6(solid_tau(mat, load_m33(F, p), Jp[p]))
