"""Phase 2, binned: P2G with one set of global atomics per occupied stencil, not per particle.

The reference P2G (p2g.py) adds every particle's 27 x 4 contributions to the grid with
global atomics; at 8 particles per cell those atomics are most of a substep (an H100 adds
~130 G floats/s this way: 15 of 19 ms a substep at 19M particles). Here:

    1. key = the particle's base node (the corner of its 3x3x3 stencil, with its field),
       for each slot s of an order `idx` (a permutation of the particles);
    2. at the first substep of a chunk (stepper.py), (key, idx) are radix-sorted, so the
       particles sharing a stencil sit next to each other; the other substeps keep that
       order (particles move a fraction of a cell per substep, so it stays nearly sorted:
       a particle that changed cell only splits a run, it is never lost);
    3. per slot: its particle's mass, momentum, MLS affine term (the same `particle_affine`
       as the reference) and stencil offset fx go to a payload array in slot order, and the
       starts of runs of equal keys are found (a scan);
    4. nine threads per run, one per (i, j) row of the stencil, each sum the run's
       contributions to their three nodes and add each sum with one atomic per channel.
       The run's payload is read by its nine threads at once (one load serves them all).

Measured on an H100 (19M particles, snow, fast mode): P2G 15.1 -> 6.8 ms a substep (scatter
4.2, payload 1.6, keys 0.3, the scan and the sort once a chunk ~0.6). Also measured and
dropped: re-sorting every substep (10.6 -> 11.4 ms a substep), bins of 2^3 cells sharing a
4^3-node stencil (fewer atomics, but 2.4x the weight evaluations: scatter 4.9 -> 5.9 ms),
consecutive threads taking one stencil row of consecutive runs, so that a warp's atomics land
on consecutive nodes (scatter 4.2 -> 6.6 ms), and one thread per run looping over the 27
nodes (no faster than the reference's atomics).

Deterministic mode: each contribution is rounded to fixed point exactly as in the
reference before it is summed (integers, so neither the order nor the runs matter), so the
grid is bit-identical to the reference on the CPU. On CUDA the compiler contracts
multiply-adds differently in the two kernels, so the last bits differ (measured on an H100,
grid 32: max |difference| over x, v, C, F of 6.5e-4 after 308 substeps of snow, 2.1e-4 of
water); each path replays bit-identically. Fast mode: the float sums are ordered
differently (the reference's atomics have no order either). Extra device memory: 92 bytes
per particle (payload 64, keys and order 16 for the sort's double buffers, run flags /
offsets / starts 12). Multi-field scenes use the reference P2G (the mass-gradient channels
are not binned).
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from .constitutive import MaterialParams, bspline_weights
from .p2g import P2GParams, make_particle_affine, to_fixed
from .state import SceneFlags
from .stepper import SubstepDev

__all__ = ["BinnedP2G"]

NO_KEY = wp.constant(0x7FFFFFFF)  # tracers and removed particles: sorted last, never scattered
ROWS = 9  # threads per run: one per (i, j) row of the 3x3x3 stencil
SCATTER_THREADS = 1 << 22  # the scatter's grid-stride width at most: the run count is known on the device only
vec12l = wp.types.vector(length=12, dtype=wp.int64)  # deterministic sums of a row: node k, channel c at 4 k + c


@wp.func
def base_node(xp: wp.vec3, inv_dx: float) -> wp.vec3i:
    """The corner node of a particle's stencil, as the reference P2G computes it."""
    xg = xp * inv_dx
    return wp.vec3i(int(wp.floor(xg[0] - 0.5)), int(wp.floor(xg[1] - 0.5)), int(wp.floor(xg[2] - 0.5)))


@wp.kernel(enable_backward=False)
def _keys(pp: P2GParams, x: wp.array(dtype=wp.vec3), alive: wp.array(dtype=wp.int32), mass: wp.array(dtype=float),
          field_id: wp.array(dtype=wp.int32), idx: wp.array(dtype=wp.int32), keys: wp.array(dtype=wp.int32),
          sub: wp.array(dtype=SubstepDev)):
    s = wp.tid()
    if sub[0].active == 0:
        return
    p = idx[s]
    if alive[p] == 0 or mass[p] == 0.0:
        keys[s] = NO_KEY
        return
    b = base_node(x[p], pp.inv_dx)
    keys[s] = ((b[0] + field_id[p] * pp.nodes) * pp.nodes + b[1]) * pp.nodes + b[2]


@wp.kernel(enable_backward=False)
def _starts(flag: wp.array(dtype=wp.int32), pos: wp.array(dtype=wp.int32), n: int, start: wp.array(dtype=wp.int32),
            n_runs: wp.array(dtype=wp.int32), sub: wp.array(dtype=SubstepDev)):
    s = wp.tid()
    if sub[0].active == 0:
        return
    if flag[s] != 0:
        start[pos[s]] = s
    if s == n - 1:
        n_runs[0] = pos[s] + flag[s]


@functools.lru_cache(maxsize=None)
def make_binned(flags: SceneFlags):
    """(payload, scatter) kernels for the scene's materials."""
    particle_affine = make_particle_affine(flags)

    @wp.kernel(enable_backward=False, module=flags.key + "_bin")
    def payload(pp: P2GParams, keys: wp.array(dtype=wp.int32), idx: wp.array(dtype=wp.int32),
                x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), C: wp.array(dtype=wp.mat33),
                F: wp.array(dtype=wp.mat33), J: wp.array(dtype=float), Jp: wp.array(dtype=float),
                mass: wp.array(dtype=float), volume: wp.array(dtype=float), material: wp.array(dtype=wp.int32),
                materials: wp.array(dtype=MaterialParams),
                px: wp.array(dtype=wp.vec3), pm: wp.array(dtype=float), pmv: wp.array(dtype=wp.vec3),
                paff: wp.array(dtype=wp.mat33), flag: wp.array(dtype=wp.int32), sub: wp.array(dtype=SubstepDev)):
        s = wp.tid()
        if sub[0].active == 0:
            return
        key = keys[s]
        f = int(0)
        if key != NO_KEY and (s == 0 or keys[s - 1] != key):
            f = 1
        flag[s] = f
        if key == NO_KEY:
            return
        pp.dt = sub[0].dt
        p = idx[s]
        m = mass[p]
        paff[s] = particle_affine(pp, materials[material[p]], F, J, Jp, C, volume, p, m)
        pmv[s] = m * v[p]
        pm[s] = m
        # fx as the reference computes it (same expressions, so the same rounding and, on
        # CUDA, the same multiply-add contraction)
        xg = x[p] * pp.inv_dx
        b = base_node(x[p], pp.inv_dx)
        px[s] = xg - wp.vec3(float(b[0]), float(b[1]), float(b[2]))

    @wp.kernel(enable_backward=False, module=flags.key + "_bin")
    def scatter(pp: P2GParams, keys: wp.array(dtype=wp.int32), start: wp.array(dtype=wp.int32),
                n_runs: wp.array(dtype=wp.int32), n: int, stride: int, px: wp.array(dtype=wp.vec3), pm: wp.array(dtype=float),
                pmv: wp.array(dtype=wp.vec3), paff: wp.array(dtype=wp.mat33),
                grid_m: wp.array3d(dtype=float), grid_mv: wp.array3d(dtype=wp.vec3),
                grid_fixed: wp.array4d(dtype=wp.int64), sub: wp.array(dtype=SubstepDev)):
        t = wp.tid()
        if sub[0].active == 0:
            return
        nn = pp.nodes
        dx = 1.0 / pp.inv_dx
        for item in range(t, n_runs[0] * ROWS, stride):
            r = item // ROWS
            i = (item % ROWS) // 3
            j = item % 3
            s0 = start[r]
            key = keys[s0]
            bk = key % nn
            bj = (key // nn) % nn
            bf = key // (nn * nn)  # field * nodes + bi
            m_sum = wp.vec3(0.0)  # per node k = 0, 1, 2
            mv0 = wp.vec3(0.0)
            mv1 = wp.vec3(0.0)
            mv2 = wp.vec3(0.0)
            q = vec12l()
            s = s0
            while s < n:
                if keys[s] != key:
                    break
                # the reference's numbers, particle by particle (p2g.py)
                fx = px[s]
                W = bspline_weights(fx)
                m = pm[s]
                mv = pmv[s]
                aff = paff[s]
                for k in range(3):
                    w = W[i, 0] * W[j, 1] * W[k, 2]
                    dpos = (wp.vec3(float(i), float(j), float(k)) - fx) * dx
                    mom = w * (mv + aff * dpos)
                    if pp.deterministic != 0:
                        q[4 * k] = q[4 * k] + to_fixed(w * m, pp.q_mass_inv)
                        for c in range(3):
                            q[4 * k + 1 + c] = q[4 * k + 1 + c] + to_fixed(mom[c], pp.q_mom_inv)
                    else:
                        m_sum[k] = m_sum[k] + w * m
                        if k == 0:
                            mv0 += mom
                        elif k == 1:
                            mv1 += mom
                        else:
                            mv2 += mom
                s += 1
            for k in range(3):
                if pp.deterministic != 0:
                    for c in range(4):
                        wp.atomic_add(grid_fixed, bf + i, bj + j, bk + k, c, q[4 * k + c])
                else:
                    wp.atomic_add(grid_m, bf + i, bj + j, bk + k, m_sum[k])
            if pp.deterministic == 0:
                wp.atomic_add(grid_mv, bf + i, bj + j, bk, mv0)
                wp.atomic_add(grid_mv, bf + i, bj + j, bk + 1, mv1)
                wp.atomic_add(grid_mv, bf + i, bj + j, bk + 2, mv2)

    return payload, scatter


class BinnedP2G:
    """Scratch buffers of the binned P2G for one particle count, the particles' order, and
    its launches."""

    def __init__(self, flags: SceneFlags, n: int, device):
        self.n, self.device = n, device
        self.payload, self.scatter = make_binned(flags)
        with wp.ScopedDevice(device):
            self.keys = wp.empty(2 * n, dtype=wp.int32)  # radix_sort_pairs sorts in double buffers
            self.idx = wp.array(np.tile(np.arange(n, dtype=np.int32), 2))  # slot -> particle
            self.flag = wp.empty(n, dtype=wp.int32)
            self.pos = wp.empty(n, dtype=wp.int32)
            self.start = wp.empty(n, dtype=wp.int32)
            self.n_runs = wp.zeros(1, dtype=wp.int32)
            self.px = wp.empty(n, dtype=wp.vec3)
            self.pm = wp.empty(n, dtype=float)
            self.pmv = wp.empty(n, dtype=wp.vec3)
            self.paff = wp.empty(n, dtype=wp.mat33)

    def launch(self, pp: P2GParams, state, cur, materials, grid_m, grid_mv, grid_fixed, sub, *, sort: bool) -> None:
        """Scatter `cur` onto the grid; sort: re-sort the particles' order first."""
        n, dev = self.n, self.device
        wp.launch(_keys, dim=n, device=dev, inputs=[pp, cur.x, cur.alive, state.mass, state.field_id, self.idx,
                                                     self.keys, sub])
        if sort:
            wp.utils.radix_sort_pairs(self.keys, self.idx, n)
        wp.launch(self.payload, dim=n, device=dev, inputs=[
            pp, self.keys, self.idx, cur.x, cur.v, cur.C, cur.F, cur.J, cur.Jp, state.mass, state.volume,
            state.material, materials, self.px, self.pm, self.pmv, self.paff, self.flag, sub])
        wp.utils.array_scan(self.flag, self.pos, inclusive=False)
        wp.launch(_starts, dim=n, device=dev, inputs=[self.flag, self.pos, n, self.start, self.n_runs, sub])
        threads = min(ROWS * n, SCATTER_THREADS)
        wp.launch(self.scatter, dim=threads, device=dev, inputs=[
            pp, self.keys, self.start, self.n_runs, n, threads, self.px, self.pm, self.pmv, self.paff,
            grid_m, grid_mv, grid_fixed, sub])

    def nbytes(self) -> int:
        return int(sum(a.capacity for a in (self.keys, self.idx, self.flag, self.pos, self.start, self.px, self.pm,
                                            self.pmv, self.paff)))
