"""Phase 2, binned: P2G with one set of global atomics per occupied stencil, not per particle.

The reference P2G (p2g.py) adds every particle's 27 x 4 contributions to the grid with
global atomics; at 8 particles per cell those atomics are most of a substep. Here:

    1. key = the particle's base node (the corner of its 3x3x3 stencil, with its field);
    2. particles sorted by key (radix sort of (key, index), every substep: they move);
    3. per particle, in sorted order: its mass, momentum, MLS affine term (the same
       `particle_affine` as the reference) and stencil offset fx go to a payload array, and the starts of runs of
       equal keys are found (a scan);
    4. one thread per run (the ~8 particles sharing a stencil) sums their contributions to
       each of the 27 nodes and adds the sum with one atomic per node and channel.

Deterministic mode: each contribution is rounded to fixed point exactly as in the
reference before it is summed (integers), so the grid is bit-identical to the reference on
the CPU. On CUDA the compiler contracts multiply-adds differently in the two kernels, so the
last bits differ (measured on an H100, grid 32: max |difference| over x, v, C, F of 6.5e-4
after 308 substeps of snow, 2.1e-4 of water); each path replays bit-identically.
Fast mode: the float sums are ordered differently (the reference's atomics have no order
either). Extra device memory: 92 bytes per particle (payload 64, keys and indices 16 for
the sort's double buffers, run flags / offsets / starts 12). Multi-field scenes use the
reference P2G (the mass-gradient channels are not binned).
"""

from __future__ import annotations

import functools

import warp as wp

from .constitutive import MaterialParams, bspline_weights
from .p2g import P2GParams, make_particle_affine, to_fixed
from .state import SceneFlags
from .stepper import SubstepDev

__all__ = ["BinnedP2G"]

NO_KEY = wp.constant(0x7FFFFFFF)  # tracers and removed particles: sorted last, never scattered


@wp.kernel(enable_backward=False)
def _keys(pp: P2GParams, x: wp.array(dtype=wp.vec3), alive: wp.array(dtype=wp.int32), mass: wp.array(dtype=float),
          field_id: wp.array(dtype=wp.int32), keys: wp.array(dtype=wp.int32), idx: wp.array(dtype=wp.int32),
          n_runs: wp.array(dtype=wp.int32), sub: wp.array(dtype=SubstepDev)):
    p = wp.tid()
    if sub[0].active == 0:
        return
    if p == 0:
        n_runs[0] = 0
    idx[p] = p
    if alive[p] == 0 or mass[p] == 0.0:
        keys[p] = NO_KEY
        return
    xg = x[p] * pp.inv_dx
    bi = int(wp.floor(xg[0] - 0.5)) + field_id[p] * pp.nodes
    bj = int(wp.floor(xg[1] - 0.5))
    bk = int(wp.floor(xg[2] - 0.5))
    keys[p] = (bi * pp.nodes + bj) * pp.nodes + bk


@wp.kernel(enable_backward=False)
def _starts(keys: wp.array(dtype=wp.int32), flag: wp.array(dtype=wp.int32), pos: wp.array(dtype=wp.int32), n: int,
            start: wp.array(dtype=wp.int32), n_runs: wp.array(dtype=wp.int32), sub: wp.array(dtype=SubstepDev)):
    s = wp.tid()
    if sub[0].active == 0:
        return
    if flag[s] != 0:
        start[pos[s]] = s
    if keys[s] != NO_KEY:
        if s == n - 1 or keys[s + 1] == NO_KEY:
            end = pos[s] + flag[s]
            start[end] = s + 1
            n_runs[0] = end


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
        bi = int(wp.floor(xg[0] - 0.5))
        bj = int(wp.floor(xg[1] - 0.5))
        bk = int(wp.floor(xg[2] - 0.5))
        px[s] = xg - wp.vec3(float(bi), float(bj), float(bk))

    @wp.kernel(enable_backward=False, module=flags.key + "_bin")
    def scatter(pp: P2GParams, keys: wp.array(dtype=wp.int32), start: wp.array(dtype=wp.int32),
                n_runs: wp.array(dtype=wp.int32), px: wp.array(dtype=wp.vec3), pm: wp.array(dtype=float),
                pmv: wp.array(dtype=wp.vec3), paff: wp.array(dtype=wp.mat33),
                grid_m: wp.array3d(dtype=float), grid_mv: wp.array3d(dtype=wp.vec3),
                grid_fixed: wp.array4d(dtype=wp.int64), sub: wp.array(dtype=SubstepDev)):
        r = wp.tid()
        if sub[0].active == 0 or r >= n_runs[0]:
            return
        s0 = start[r]
        s1 = start[r + 1]
        key = keys[s0]
        nn = pp.nodes
        bk = key % nn
        bj = (key // nn) % nn
        bf = key // (nn * nn)  # field * nodes + bi
        inv_dx = pp.inv_dx
        dx = 1.0 / inv_dx
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    node = wp.vec3(float(i), float(j), float(k))
                    m_sum = float(0.0)
                    mv_sum = wp.vec3(0.0)
                    q0 = wp.int64(0)
                    q1 = wp.int64(0)
                    q2 = wp.int64(0)
                    q3 = wp.int64(0)
                    for s in range(s0, s1):
                        # the reference's numbers, particle by particle (p2g.py)
                        fx = px[s]
                        W = bspline_weights(fx)
                        w = W[i, 0] * W[j, 1] * W[k, 2]
                        m = pm[s]
                        dpos = (node - fx) * dx
                        mom = w * (pmv[s] + paff[s] * dpos)
                        if pp.deterministic != 0:
                            q0 += to_fixed(w * m, pp.q_mass_inv)
                            q1 += to_fixed(mom[0], pp.q_mom_inv)
                            q2 += to_fixed(mom[1], pp.q_mom_inv)
                            q3 += to_fixed(mom[2], pp.q_mom_inv)
                        else:
                            m_sum += w * m
                            mv_sum += mom
                    if pp.deterministic != 0:
                        wp.atomic_add(grid_fixed, bf + i, bj + j, bk + k, 0, q0)
                        wp.atomic_add(grid_fixed, bf + i, bj + j, bk + k, 1, q1)
                        wp.atomic_add(grid_fixed, bf + i, bj + j, bk + k, 2, q2)
                        wp.atomic_add(grid_fixed, bf + i, bj + j, bk + k, 3, q3)
                    else:
                        wp.atomic_add(grid_m, bf + i, bj + j, bk + k, m_sum)
                        wp.atomic_add(grid_mv, bf + i, bj + j, bk + k, mv_sum)

    return payload, scatter


class BinnedP2G:
    """Scratch buffers of the binned P2G for one particle count, and its launches."""

    def __init__(self, flags: SceneFlags, n: int, device):
        self.n, self.device = n, device
        self.payload, self.scatter = make_binned(flags)
        with wp.ScopedDevice(device):
            self.keys = wp.empty(2 * n, dtype=wp.int32)  # radix_sort_pairs sorts in double buffers
            self.idx = wp.empty(2 * n, dtype=wp.int32)
            self.flag = wp.empty(n, dtype=wp.int32)
            self.pos = wp.empty(n, dtype=wp.int32)
            self.start = wp.empty(n + 1, dtype=wp.int32)
            self.n_runs = wp.zeros(1, dtype=wp.int32)
            self.px = wp.empty(n, dtype=wp.vec3)
            self.pm = wp.empty(n, dtype=float)
            self.pmv = wp.empty(n, dtype=wp.vec3)
            self.paff = wp.empty(n, dtype=wp.mat33)

    def launch(self, pp: P2GParams, state, cur, materials, grid_m, grid_mv, grid_fixed, sub) -> None:
        n, dev = self.n, self.device
        wp.launch(_keys, dim=n, device=dev, inputs=[pp, cur.x, cur.alive, state.mass, state.field_id, self.keys,
                                                     self.idx, self.n_runs, sub])
        wp.utils.radix_sort_pairs(self.keys, self.idx, n)
        wp.launch(self.payload, dim=n, device=dev, inputs=[
            pp, self.keys, self.idx, cur.x, cur.v, cur.C, cur.F, cur.J, cur.Jp, state.mass, state.volume,
            state.material, materials, self.px, self.pm, self.pmv, self.paff, self.flag, sub])
        wp.utils.array_scan(self.flag, self.pos, inclusive=False)
        wp.launch(_starts, dim=n, device=dev, inputs=[self.keys, self.flag, self.pos, n, self.start, self.n_runs, sub])
        wp.launch(self.scatter, dim=n, device=dev, inputs=[
            pp, self.keys, self.start, self.n_runs, self.px, self.pm, self.pmv, self.paff,
            grid_m, grid_mv, grid_fixed, sub])

    def nbytes(self) -> int:
        return int(sum(a.capacity for a in (self.keys, self.idx, self.flag, self.pos, self.start, self.px, self.pm,
                                            self.pmv, self.paff)))
