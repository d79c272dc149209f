"""The adaptive stepper on the device: `Solver.advance` without a host round trip per substep.

The host loop in `Solver._advance_host` (the reference) reads the statistics back after
every substep to choose the next dt and to accept or reject the substep. Here the same
decisions run in two one-thread kernels around each substep, in float64 like the host:

    begin: dt from the CFL condition and the clock (or stop: finished, dt < dt_min, too many
           substeps), dt / damping / drag factors for the phase kernels, statistics reset
    pose:  the colliders' poses and velocities over the substep (scenes with colliders)
    clear grid -> P2G -> grid update -> G2P        (phase kernels return at once when stopped)
    end:   reject (dt_scale halved, the chunk stops so `cur` stays current) or accept
           (clock, report accumulators, dt_scale regrown)

A chunk of such substeps is launched at once (on CUDA: one CUDA graph per chunk length and
buffer parity); the host reads the clock once per chunk. A rejected substep stops its chunk
and the next chunk retries it at half dt from the same state, exactly as the host loop does,
so the dt sequence and the particles are the same as the reference: bit-identical on the CPU
and, in deterministic mode with the reference P2G, on CUDA too (the brick one differs in the
last bits there, see p2g_brick.py).
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from .colliders import ColliderParams, pose_collider
from .materials import Mode
from .slots import REJECTING, Clock, Count, Stat, Status

__all__ = [
    "SubstepDev",
    "StepperParams",
    "WaveParams",
    "make_clock_kernels",
    "pose_colliders",
    "CHUNKS",
    "sum_partials",
]

CHUNKS = (1, 2, 4, 8, 16, 32)  # substeps per chunk: each length is one captured graph
REJECT_MASK = wp.constant(sum(1 << int(c) for c in REJECTING))  # counters that reject a substep


@wp.struct
class SubstepDev:
    """What the phase kernels read per substep instead of their launch parameters:
    dt (s), damping_factor (1 - damping dt), affine_keep (1 - drag dt), active (0: skip)."""

    dt: float
    damping_factor: float
    affine_keep: float
    active: int


@wp.struct
class StepperParams:
    """The stepper's knobs, float64 as on the host (see SolverConfig)."""

    cfl: wp.float64
    dx: wp.float64
    dt_max: wp.float64
    dt_min: wp.float64
    damping: wp.float64
    drag: wp.float64
    max_substeps: wp.float64
    time_scale: wp.float64
    n_materials: int
    n_counts: int


@wp.struct
class WaveParams:
    """Per material: mode; stiff = lambda0 + 2 mu0 (solids) or K gamma (water); gamma; density."""

    mode: int
    stiff: wp.float64
    gamma: wp.float64
    density: wp.float64


def wave_table(materials) -> list:
    out = []
    for m in materials:
        w = WaveParams()
        w.mode = int(m.mode)
        w.stiff = (m.bulk_modulus * m.eos_gamma) if m.mode == Mode.WATER else (m.lambda0 + 2.0 * m.mu0)
        w.gamma, w.density = float(m.eos_gamma), float(m.density)
        out.append(w)
    return out


@wp.func
def wave_speed(w: WaveParams, hardening: wp.float64, j_min: wp.float64) -> wp.float64:
    """materials.Material.wave_speed, operation for operation in float64."""
    if w.mode == int(Mode.TRACER):
        return wp.float64(0.0)
    if w.mode == int(Mode.WATER):
        k_eff = w.stiff * wp.pow(wp.max(j_min, wp.float64(1e-4)), -w.gamma)
        return wp.sqrt(k_eff / w.density)
    h = wp.float64(1.0)
    if w.mode == int(Mode.SNOW):
        h = wp.max(wp.float64(1.0), hardening)
    return wp.sqrt(w.stiff * h / w.density)


@wp.func
def c_max(sp: StepperParams, waves: wp.array(dtype=WaveParams), clk: wp.array(dtype=wp.float64)) -> wp.float64:
    c = wp.float64(0.0)
    for i in range(sp.n_materials):
        c = wp.max(c, wave_speed(waves[i], clk[Clock.MAX_HARDENING], clk[Clock.WATER_J_MIN]))
    return c


@wp.func
def stop(clk: wp.array(dtype=wp.float64), sub: wp.array(dtype=SubstepDev), status: int):
    clk[Clock.STATUS] = wp.float64(status)
    s = sub[0]
    s.active = 0
    sub[0] = s


@functools.lru_cache(maxsize=None)
def make_clock_kernels(snow: bool, water: bool):
    """(begin, end) kernels of one substep; snow / water: which clock fields the scene updates."""

    @wp.kernel(enable_backward=False, module=f"mpmfx_mpm_clock_{int(snow)}{int(water)}")
    def begin(
        sp: StepperParams,
        waves: wp.array(dtype=WaveParams),
        clk: wp.array(dtype=wp.float64),
        sub: wp.array(dtype=SubstepDev),
        stats: wp.array(dtype=float),
        stats_init: wp.array(dtype=float),
        counts: wp.array(dtype=wp.int32),
    ):
        if int(clk[Clock.STATUS]) != Status.RUNNING:
            stop(clk, sub, int(clk[Clock.STATUS]))
            return
        c = c_max(sp, waves, clk) + clk[Clock.MAX_SPEED]
        dt_cfl = sp.dt_max
        if c > wp.float64(0.0):
            dt_cfl = wp.min(sp.dt_max, sp.cfl * sp.dx / c)
        dt_cfl = dt_cfl * clk[Clock.DT_SCALE]
        clk[Clock.DT_CFL] = dt_cfl
        if dt_cfl < sp.dt_min:
            stop(clk, sub, Status.DT_TOO_SMALL)
            return
        if clk[Clock.N_SUB] >= sp.max_substeps:
            stop(clk, sub, Status.TOO_MANY)
            return
        remaining = clk[Clock.TOTAL] - clk[Clock.DONE]
        last = remaining <= dt_cfl * (wp.float64(1.0) + wp.float64(1e-6))
        dt = dt_cfl
        if last:
            dt = remaining
        elif remaining < wp.float64(2.0) * dt_cfl:
            dt = wp.float64(0.5) * remaining
        clk[Clock.DT] = dt
        clk[Clock.LAST] = wp.float64(0.0)
        if last:
            clk[Clock.LAST] = wp.float64(1.0)
        s = SubstepDev()
        s.dt = float(dt)
        s.damping_factor = float(wp.max(wp.float64(0.0), wp.float64(1.0) - sp.damping * dt))
        s.affine_keep = float(wp.max(wp.float64(0.0), wp.float64(1.0) - sp.drag * dt))
        s.active = 1
        sub[0] = s
        for i in range(stats.shape[0]):
            stats[i] = stats_init[i]
        for i in range(counts.shape[0]):
            counts[i] = 0

    @wp.kernel(enable_backward=False, module=f"mpmfx_mpm_clock_{int(snow)}{int(water)}")
    def end(
        sp: StepperParams,
        waves: wp.array(dtype=WaveParams),
        clk: wp.array(dtype=wp.float64),
        sub: wp.array(dtype=SubstepDev),
        stats: wp.array(dtype=float),
        counts: wp.array(dtype=wp.int32),
        last_bad: wp.array(dtype=wp.int32),
    ):
        if sub[0].active == 0:
            return
        bad = int(0)
        for i in range(int(Count.PER_MATERIAL)):
            if (REJECT_MASK >> i) & 1 != 0:
                bad += counts[i]
        if bad > 0:  # redo at half dt (Ziran), from the same state: stop the chunk here
            clk[Clock.N_REJ] = clk[Clock.N_REJ] + wp.float64(1.0)
            clk[Clock.DT_SCALE] = clk[Clock.DT_SCALE] * wp.float64(0.5)
            clk[Clock.HAS_BAD] = wp.float64(1.0)
            for i in range(sp.n_counts):
                last_bad[i] = counts[i]
            stop(clk, sub, Status.REJECTED)
            return
        dt = clk[Clock.DT]
        if clk[Clock.LAST] != wp.float64(0.0):
            clk[Clock.DONE] = clk[Clock.TOTAL]
        else:
            clk[Clock.DONE] = clk[Clock.DONE] + dt
        clk[Clock.N_SUB] = clk[Clock.N_SUB] + wp.float64(1.0)
        clk[Clock.SUBSTEPS] = clk[Clock.SUBSTEPS] + wp.float64(1.0)
        clk[Clock.LAST_DT] = dt
        clk[Clock.DT_SCALE] = wp.min(wp.float64(1.0), clk[Clock.DT_SCALE] * wp.float64(1.25))
        clk[Clock.MAX_SPEED] = wp.float64(stats[Stat.MAX_SPEED])
        if wp.static(snow):
            clk[Clock.MAX_HARDENING] = wp.max(wp.float64(1.0), wp.float64(stats[Stat.MAX_HARDENING]))
        if wp.static(water):
            clk[Clock.WATER_J_MIN] = wp.min(wp.float64(1.0), wp.float64(stats[Stat.WATER_J_MIN]))
        clk[Clock.DT_MIN] = wp.min(clk[Clock.DT_MIN], dt)
        clk[Clock.DT_MAX] = wp.max(clk[Clock.DT_MAX], dt)
        c = c_max(sp, waves, clk) + clk[Clock.MAX_SPEED]
        clk[Clock.CFL_USED] = wp.max(clk[Clock.CFL_USED], dt * c / sp.dx)
        clk[Clock.VMAX] = wp.max(clk[Clock.VMAX], clk[Clock.MAX_SPEED])
        if stats[Stat.J_MIN] <= stats[Stat.J_MAX]:
            clk[Clock.J_MIN] = wp.min(clk[Clock.J_MIN], wp.float64(stats[Stat.J_MIN]))
            clk[Clock.J_MAX] = wp.max(clk[Clock.J_MAX], wp.float64(stats[Stat.J_MAX]))
        clk[Clock.LOST] = clk[Clock.LOST] + wp.float64(counts[Count.LOST])
        clk[Clock.INVERTED] = clk[Clock.INVERTED] + wp.float64(counts[Count.INVERTED])
        if clk[Clock.LAST] != wp.float64(0.0):
            stop(clk, sub, Status.FINISHED)

    return begin, end


@wp.kernel(enable_backward=False)
def pose_colliders(
    sp: StepperParams,
    clk: wp.array(dtype=wp.float64),
    keys_t: wp.array(dtype=wp.float64),
    keys_p: wp.array(dtype=wp.vec3),
    keys_q: wp.array(dtype=wp.quat),
    offsets: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    out: wp.array(dtype=ColliderParams),
):
    """Pose every collider for the substep `begin` set up, on the shot clock as the host loop
    does: [T0 + DONE / time_scale, T0 + (DONE + DT) / time_scale], or T1 on the last one."""
    if int(clk[Clock.STATUS]) != Status.RUNNING:
        return
    ts0 = clk[Clock.T0] + clk[Clock.DONE] / sp.time_scale
    ts1 = clk[Clock.T1]
    if clk[Clock.LAST] == wp.float64(0.0):
        ts1 = clk[Clock.T0] + (clk[Clock.DONE] + clk[Clock.DT]) / sp.time_scale
    pose_collider(wp.tid(), keys_t, keys_p, keys_q, offsets, counts, ts0, ts1, clk[Clock.DT], out)


REPORT_CHUNK = 256  # partial sums summed in order by one thread: the sums do not depend on scheduling


@wp.func
def chunk_particle(b: int, i: int, chunk: int, threads: int, coalesced: int) -> int:
    """Particle i of thread b's fixed set of `chunk` (the threads' sets cover 0..threads * chunk;
    a reduction sums its set in i order, so its partial sums never depend on scheduling).
    coalesced (a GPU): the threads' i-th particles are neighbours, so a warp reads consecutive
    memory, several times faster than runs of a thread's own; else (the
    CPU, whose threads run one after another) thread b's set is the run b * chunk + i."""
    if coalesced != 0:
        return b + i * threads
    return b * chunk + i


@wp.kernel(enable_backward=False)
def _sum_rows(src: wp.array2d(dtype=wp.float64), rows: int, out: wp.array2d(dtype=wp.float64)):
    """out[b, c] = src[b * REPORT_CHUNK : (b + 1) * REPORT_CHUNK, c] summed in order."""
    b, c = wp.tid()
    acc = wp.float64(0.0)
    for r in range(b * REPORT_CHUNK, wp.min(rows, (b + 1) * REPORT_CHUNK)):
        acc = acc + src[r, c]
    out[b, c] = acc


def sum_partials(part, device) -> np.ndarray:
    """Column sums of a (rows, columns) float64 device array of partial sums, in a fixed
    order (replays give the same bits); only the last few rows come to the host."""
    rows, cols = part.shape
    while rows > REPORT_CHUNK:
        nxt = (rows + REPORT_CHUNK - 1) // REPORT_CHUNK
        out = wp.empty((nxt, cols), dtype=wp.float64, device=device)
        wp.launch(_sum_rows, dim=(nxt, cols), device=device, inputs=[part, rows, out])
        part, rows = out, nxt
    return part.numpy().sum(axis=0)
