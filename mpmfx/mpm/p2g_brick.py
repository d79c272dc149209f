"""Phase 2, by brick: P2G summed in shared memory, one global add per node a brick touches.

The reference P2G (p2g.py) adds each particle's 27 x 4 contributions to the grid with
global atomics, which dominate a GPU substep. Here the particles are kept
in brick order (a brick: 4^3 stencil corner nodes) and one CUDA block scatters a brick:

    1. at the first substep of a chunk (chunked.py), and then every few substeps as the
       order wears (sort_cadence), the particles' order `idx` is radix-sorted by brick,
       then by corner node inside it, and the slot ranges of equal bricks (segments) are
       found; that substep's scatter reads particle idx[slot], and its G2P stores each
       particle in its slot (g2p.py, State: storage order), so the substeps between read the
       slots as they lie in memory and keep the segments (particles move a fraction of a cell
       a substep);
    2. per substep, per segment, one block zeroes a window of 8^3 nodes in shared memory
       (the brick's 4^3 corners, one node of slack below and above, and the stencil's reach);
    3. in rounds of 128 consecutive slots (coalesced reads) each thread computes one
       particle's mass, momentum, MLS affine term and fx (the reference's numbers:
       `particle_affine`, the same expressions) and parks them in shared memory, the momentum
       as its polynomial in the node offset (i, j, k): q + A (i, j, k), q = m v - A fx, A the
       affine term times dx;
    4. nine threads per run of parked particles sharing a stencil (one per stencil row) sum
       the run's contributions to their three nodes in registers and add each sum, rounded to
       fixed point, to the window once per channel: ~8x fewer shared atomics than one per
       particle, and integer ones (see _WINDOW);
    5. the block adds each touched window node to the grid, one global atomic per channel
       (~8x fewer than the runs would need): integers to the fixed-point grid in
       deterministic mode, floats in fast mode.
    A particle that left the window since the sort (more than one cell out of its brick)
    adds to the grid directly, as the reference does: slower, never lost.
    6. every block marks the 3^3 node bricks around its brick (its window's), and a fallback
       particle the node bricks of its stencil: the next substep of the chunk clears only the
       marked bricks (clear_grid.py) and the grid update runs only there (grid_update.py), as
       a shot's grid is mostly empty (hero_dam: 12.8k of 274.6k bricks marked).

Why this shape: same-address shared atomics serialise, so a thread adding its own particle to
the window is slow; summing a run in registers and adding the sum once is several times
faster. Capping a thread's registers (MAX_REGISTERS) lets more blocks onto a multiprocessor:
64 is the fastest cap for this code (the compiler takes 128 unbounded), with the run's weights
kept in registers (row_weight). Current P2G figures: docs/benchmarks.md.

The window holds fixed point in both modes (the reference's quanta, p2g.py), so its sums are
exact and order-free. A run's float sums are deterministic too: its particles are summed in
slot order, and the sort starts from particle order each time, so ties keep particle order
whatever happened before (a run resumed from a checkpoint sums as the first did). So replays
are bit-identical in deterministic mode, while against the reference (which rounds each
particle's contribution) a node differs by about a quantum a particle of its runs: rounding
the sums instead is ~8x fewer float-to-int64 conversions and int64 registers. A run task
(add_run) forms its row's momentum q + A (i, j, 0) once a particle and steps column 2 of A for
k = 1, 2, rather than computing w (m v + aff dpos) for each node. The park holds fx, not the
nine weights, which keeps it small enough for eight blocks a multiprocessor. The window holds
32-bit words, which shared memory adds natively (float and int64 adds there are
compare-and-swap loops).

Extra device memory: 28 bytes a particle (keys and order double-buffered for the sort 16,
flags / offsets / segment starts 12), and 4 bytes a node brick for the marks; no payload array.

On the CPU the same kernel runs with one thread a block (the shared arrays are static ones
and the block's phases run in sequence), so the tests check the segments, the window test,
the runs and the fallback there; only the barriers and the warp vote are CUDA's own.
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from .bricks import (
    BRICK,
    FRAG_FALLBACKS,
    FRAG_PIECES,
    FRAG_SLOTS,
    FRAG_SUBSTEPS,
    base_node,
    brick_keys,
    node_brick,
    seg_flags,
    seg_starts,
)
from .constitutive import MaterialParams, bspline_weights, vec6
from .p2g import P2GParams, make_particle_affine, to_fixed
from .state import SceneFlags
from .stepper import SubstepDev

__all__ = ["BrickP2G"]

WIN = 8  # window nodes per axis: BRICK + 1 slack below + 1 above + the stencil's 2
WIN_NODES = WIN * WIN * WIN
BLOCK_CUDA = 128  # threads a block on CUDA, and slots parked a round
MAX_REGISTERS = 64  # a thread's registers (the compiler takes 128 unbounded: see the docstring)
MAX_BLOCKS = 1 << 15  # blocks at most; each walks segments block, block + MAX_BLOCKS, ...
PARKED = 16  # floats a parked particle: m, q (3), A (9), fx (3) (the scatter's park)

# Shared arrays live in native functions (static, so every call in a block reaches the same
# memory); each function owns its arrays. On the CPU (one thread a block) they are plain
# static arrays and the barriers vanish.
#
# The window: 4 channel planes (mass, momentum x, y, z) of WIN_NODES nodes, in fixed point
# (p2g.to_fixed), each value two 32-bit words (low, high): shared memory has native 32-bit
# integer atomics only (a float or 64-bit add there compiles to a compare-and-swap loop,
# ATOMS.CAST.SPIN on sm_90). An add is exact 64-bit addition: the low word's atomic returns
# the word before it, and its carry goes into the high word's add. Ops: 0 zero, 1 add, 2 read,
# 3 barrier. (Channel planes: the threads of a run add one channel at a time, to nodes 8 and
# 64 words apart, which interleaved channels would crowd onto fewer banks.)
_WINDOW = """
#if defined(__CUDA_ARCH__)
__shared__ unsigned int win_lo[4 * {N}];
__shared__ unsigned int win_hi[4 * {N}];
#else
static unsigned int win_lo[4 * {N}];
static unsigned int win_hi[4 * {N}];
#endif
if (op == 0) {{ win_lo[e] = 0u; win_hi[e] = 0u; }}
else if (op == 1) {{
    unsigned long long u = (unsigned long long)value;
    unsigned int lo = (unsigned int)u, hi = (unsigned int)(u >> 32);
#if defined(__CUDA_ARCH__)
    unsigned int old = atomicAdd(&win_lo[e], lo);
    atomicAdd(&win_hi[e], hi + (old + lo < old ? 1u : 0u));
#else
    unsigned int old = win_lo[e];
    win_lo[e] = old + lo;
    win_hi[e] += hi + (old + lo < old ? 1u : 0u);
#endif
}}
else if (op == 3) {{
#if defined(__CUDA_ARCH__)
    __syncthreads();
#endif
}}
return (long long)(((unsigned long long)win_hi[e] << 32) | (unsigned long long)win_lo[e]);
"""


# The parked particles of a round: PARKED planes of floats, and each slot's window code
# (corner node inside the window, or -2: nothing parked); ops: 1 write, 2 read a float,
# 4 write, 5 read a code.
_PARK = """
#if defined(__CUDA_ARCH__)
__shared__ float park[{F} * {B}];
__shared__ int park_code[{B}];
#else
static float park[{F} * {B}];
static int park_code[{B}];
#endif
if (op == 1) {{ park[e] = value; }}
else if (op == 2) {{ return park[e]; }}
else if (op == 4) {{ park_code[e] = (int)value; }}
else if (op == 5) {{ return (float)park_code[e]; }}
return 0.0f;
"""

# The runs of a round: op 1, called by every thread of the block with e = 1 where a run
# starts, returns the number of run starts before this thread << 16 | the block's total (a
# warp vote and the warps' counts); op 2 writes run_start[e] = value, op 3 reads it.
_RUNS = """
#if defined(__CUDA_ARCH__)
__shared__ int warp_total[32];
__shared__ int run_start[{B}];
if (op == 1) {{
    unsigned mask = __ballot_sync(0xffffffffu, e != 0);
    int w = lane >> 5, l = lane & 31;
    if (l == 0) warp_total[w] = __popc(mask);
    __syncthreads();
    int before = 0, total = 0;
    for (int i = 0; i < (nthreads + 31) / 32; ++i) {{ if (i < w) before += warp_total[i]; total += warp_total[i]; }}
    __syncthreads();
    return ((before + __popc(mask & ((1u << l) - 1u))) << 16) | total;
}}
#else
static int run_start[{B}];
if (op == 1) {{ return e != 0 ? 1 : 0; }}
#endif
if (op == 2) {{ run_start[e] = value; }}
else if (op == 3) {{ return run_start[e]; }}
return 0;
"""


@wp.func_native(_WINDOW.format(N=WIN_NODES))
def window(op: int, e: int, value: wp.int64) -> wp.int64: ...


@wp.func_native(_PARK.format(F=PARKED, B=BLOCK_CUDA))
def park(op: int, e: int, value: float) -> float: ...


@wp.func_native(_RUNS.format(B=BLOCK_CUDA))
def runs(op: int, e: int, value: int, lane: int, nthreads: int) -> int: ...


@wp.func
def mark_window(marks: wp.array(dtype=wp.int32), brick: int, nb: int, q: int):
    """Mark node brick q (0..26) of the 3^3 around `brick`: together they hold every node of
    its window (origin one node below the brick, WIN nodes an axis)."""
    b = wp.vec3i(brick // (nb * nb) + q // 9 - 1, (brick // nb) % nb + (q // 3) % 3 - 1, brick % nb + q % 3 - 1)
    if wp.min(b) >= 0 and wp.max(b) < nb:
        marks[(b[0] * nb + b[1]) * nb + b[2]] = 1


@wp.func
def row_weight(W: wp.mat33, i: int, axis: int) -> float:
    """W[i, axis] of bspline_weights for a run-time row i, by selects: a matrix indexed with a
    run-time row lives in local memory (the scatter's add_run spilled its W there: most of
    its local memory traffic). axis: a constant at every call."""
    w = W[0, axis]
    if i == 1:
        w = W[1, axis]
    elif i == 2:
        w = W[2, axis]
    return w


@functools.lru_cache(maxsize=None)
def make_brick_scatter(flags: SceneFlags, deterministic: bool):
    """The scatter kernel for the scene's materials; fast mode adds the window to the float
    grid, deterministic mode to the fixed-point one."""
    particle_affine = make_particle_affine(flags)
    one = flags.one_material
    det = deterministic

    @wp.func
    def sync():
        """A block barrier (the window's own function, so no second window is declared)."""
        window(3, 0, wp.int64(0))

    @wp.func
    def add_to_grid(
        pp: P2GParams,
        m: float,
        mv: wp.vec3,
        aff: wp.mat33,
        fx: wp.vec3,
        b: wp.vec3i,
        grid_m: wp.array3d(dtype=float),
        grid_mv: wp.array3d(dtype=wp.vec3),
        grid_fixed: wp.array4d(dtype=wp.int64),
        marks: wp.array(dtype=wp.int32),
    ):
        """A particle outside its window: its 27 x 4 contributions straight to the grid, as the
        reference adds them (p2g.py), marking the node bricks of its stencil's corners."""
        dx = 1.0 / pp.inv_dx
        nb = (pp.nodes + BRICK - 1) // BRICK
        for q in range(8):
            marks[node_brick(b[0] + 2 * (q // 4), b[1] + 2 * ((q // 2) % 2), b[2] + 2 * (q % 2), nb)] = 1
        W = bspline_weights(fx)
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    w = W[i, 0] * W[j, 1] * W[k, 2]
                    dpos = (wp.vec3(float(i), float(j), float(k)) - fx) * dx
                    mom = w * (mv + aff * dpos)
                    if wp.static(det):
                        wp.atomic_add(grid_fixed, b[0] + i, b[1] + j, b[2] + k, 0, to_fixed(w * m, pp.q_mass_inv))
                        for c in range(3):
                            wp.atomic_add(
                                grid_fixed, b[0] + i, b[1] + j, b[2] + k, 1 + c, to_fixed(mom[c], pp.q_mom_inv)
                            )
                    else:
                        wp.atomic_add(grid_m, b[0] + i, b[1] + j, b[2] + k, w * m)
                        wp.atomic_add(grid_mv, b[0] + i, b[1] + j, b[2] + k, mom)

    @wp.func
    def add_run(pp: P2GParams, u0: int, n_park: int, i: int, j: int):
        """Row (i, j) of the stencil of the parked run starting at slot u0: the run's
        contributions to its three nodes (the reference's numbers, particle by particle),
        summed in slot order, then added to the window once a node and channel (deterministic:
        each sum rounded to fixed point, see the module docstring)."""
        code = int(park(5, u0, 0.0))
        m_sum = wp.vec3(0.0)  # per node k = 0, 1, 2
        mv0 = wp.vec3(0.0)
        mv1 = wp.vec3(0.0)
        mv2 = wp.vec3(0.0)
        fi = float(i)
        fj = float(j)
        u = u0
        while u < n_park:
            if int(park(5, u, 0.0)) != code:
                break
            m = park(2, u, 0.0)
            fx = wp.vec3(
                park(2, 13 * BLOCK_CUDA + u, 0.0), park(2, 14 * BLOCK_CUDA + u, 0.0), park(2, 15 * BLOCK_CUDA + u, 0.0)
            )
            # the momentum at node (i, j, k) is q + A (i, j, k) (see the park): row (i, j)'s part once,
            # then k steps of column 2
            base = wp.vec3(0.0)
            col2 = wp.vec3(0.0)
            for c in range(3):
                base[c] = (
                    park(2, (1 + c) * BLOCK_CUDA + u, 0.0)
                    + park(2, (4 + 3 * c) * BLOCK_CUDA + u, 0.0) * fi
                    + park(2, (5 + 3 * c) * BLOCK_CUDA + u, 0.0) * fj
                )
                col2[c] = park(2, (6 + 3 * c) * BLOCK_CUDA + u, 0.0)
            W = bspline_weights(fx)
            wij = row_weight(W, i, 0) * row_weight(W, j, 1)
            w0 = wij * W[0, 2]
            w1 = wij * W[1, 2]
            w2 = wij * W[2, 2]
            m_sum += m * wp.vec3(w0, w1, w2)
            mv0 += w0 * base
            mv1 += w1 * (base + col2)
            mv2 += w2 * (base + 2.0 * col2)
            u += 1
        e = ((code // (WIN * WIN) + i) * WIN + (code // WIN) % WIN + j) * WIN + code % WIN
        for k in range(3):
            window(1, e + k, to_fixed(m_sum[k], pp.q_mass_inv))
        for c in range(3):
            window(1, (1 + c) * WIN_NODES + e, to_fixed(mv0[c], pp.q_mom_inv))
            window(1, (1 + c) * WIN_NODES + e + 1, to_fixed(mv1[c], pp.q_mom_inv))
            window(1, (1 + c) * WIN_NODES + e + 2, to_fixed(mv2[c], pp.q_mom_inv))

    @wp.func
    def flush(
        pp: P2GParams,
        e: int,
        origin: wp.vec3i,
        nn: int,
        grid_m: wp.array3d(dtype=float),
        grid_mv: wp.array3d(dtype=wp.vec3),
        grid_fixed: wp.array4d(dtype=wp.int64),
    ):
        """Window node e to the grid, one atomic a channel, if anything landed there."""
        gi = origin[0] + e // (WIN * WIN)
        gj = origin[1] + (e // WIN) % WIN
        gk = origin[2] + e % WIN
        if gi >= 0 and gj >= 0 and gk >= 0 and gi < nn and gj < nn and gk < nn:
            if wp.static(det):
                for c in range(4):
                    qv = window(2, c * WIN_NODES + e, wp.int64(0))
                    if qv != wp.int64(0):
                        wp.atomic_add(grid_fixed, gi, gj, gk, c, qv)
            else:
                qm = window(2, e, wp.int64(0))
                if qm != wp.int64(0):  # the quanta are powers of two: these divisions are exact
                    wp.atomic_add(grid_m, gi, gj, gk, float(qm) / pp.q_mass_inv)
                    wp.atomic_add(
                        grid_mv,
                        gi,
                        gj,
                        gk,
                        wp.vec3(
                            float(window(2, WIN_NODES + e, wp.int64(0))),
                            float(window(2, 2 * WIN_NODES + e, wp.int64(0))),
                            float(window(2, 3 * WIN_NODES + e, wp.int64(0))),
                        )
                        / pp.q_mom_inv,
                    )

    @wp.kernel(
        enable_backward=False,
        grid_stride=False,
        module=flags.key + ("_brick_det" if det else "_brick"),
        cuda_max_registers=MAX_REGISTERS,
    )
    def scatter(
        pp: P2GParams,
        keys: wp.array(dtype=wp.int32),
        start: wp.array(dtype=wp.int32),
        n_seg: wp.array(dtype=wp.int32),
        block: int,
        n_blocks: int,
        idx: wp.array(dtype=wp.int32),
        x: wp.array(dtype=wp.vec3),
        v: wp.array(dtype=wp.vec3),
        C: wp.array2d(dtype=wp.vec3),
        tau: wp.array(dtype=vec6),
        J: wp.array(dtype=float),
        alive: wp.array(dtype=wp.int32),
        mass: wp.array(dtype=float),
        volume: wp.array(dtype=float),
        material: wp.array(dtype=wp.int32),
        materials: wp.array(dtype=MaterialParams),
        grid_m: wp.array3d(dtype=float),
        grid_mv: wp.array3d(dtype=wp.vec3),
        grid_fixed: wp.array4d(dtype=wp.int64),
        marks: wp.array(dtype=wp.int32),
        sub: wp.array(dtype=SubstepDev),
        fresh: int,
        frag: wp.array(dtype=wp.int64),
    ):
        # fresh: 1 right after a sort, when the particles are still stored in their old order
        # and slot s holds particle idx[s]; the G2P of that substep stores them in slot order
        t = wp.tid()
        if sub[0].active == 0:
            return  # the whole launch: every thread of a block returns together
        pp.dt = sub[0].dt
        if t == 0:  # the order's wear (BrickP2G.frag): one substep more of its kind
            wp.atomic_add(frag, FRAG_SUBSTEPS + 1 - fresh, wp.int64(1))
        lane = t % block
        nn = pp.nodes
        nb = (nn + BRICK - 1) // BRICK
        n_park = wp.min(block, BLOCK_CUDA)
        seg = t // block
        while seg < n_seg[0]:  # the same count for every thread of a block: barriers stay uniform
            for ez in range(lane, 4 * WIN_NODES, block):
                window(0, ez, wp.int64(0))
            sync()
            s0 = start[seg]
            n_here = start[seg + 1] - s0
            brick = keys[s0] // 64
            origin = wp.vec3i(
                (brick // (nb * nb)) * BRICK - 1, ((brick // nb) % nb) * BRICK - 1, (brick % nb) * BRICK - 1
            )
            for r0 in range(0, n_here, n_park):
                # park: one particle a thread, consecutive slots
                code = -2
                if lane < n_park and r0 + lane < n_here:
                    p = s0 + r0 + lane
                    if fresh != 0:
                        p = idx[p]
                    m = mass[p]
                    if alive[p] != 0 and m != 0.0:
                        mid = int(0)  # (the only material's, where the scene has one: not read)
                        if wp.static(not one):
                            mid = material[p]
                        aff = particle_affine(pp, materials[mid], tau, J, C, volume, p, m)
                        mv = m * v[p]
                        xg = x[p] * pp.inv_dx
                        b = base_node(x[p], pp.inv_dx)
                        fx = xg - wp.vec3(float(b[0]), float(b[1]), float(b[2]))
                        loc = b - origin
                        if wp.min(loc) >= 0 and wp.max(loc) <= WIN - 3:
                            code = (loc[0] * WIN + loc[1]) * WIN + loc[2]
                            # parked as the momentum's polynomial in the node offset (i, j, k):
                            # m v + aff ((i, j, k) - fx) dx = q + A (i, j, k), q = m v - A fx,
                            # A = aff dx, so a run task's 3 nodes cost 3 adds and 3 scales, not 3
                            # matrix-vector products
                            A = aff * (1.0 / pp.inv_dx)
                            q = mv - A * fx
                            park(1, lane, m)
                            for c in range(3):
                                park(1, (1 + c) * BLOCK_CUDA + lane, q[c])
                                park(1, (13 + c) * BLOCK_CUDA + lane, fx[c])
                                for d in range(3):
                                    park(1, (4 + 3 * c + d) * BLOCK_CUDA + lane, A[c, d])
                        else:
                            add_to_grid(pp, m, mv, aff, fx, b, grid_m, grid_mv, grid_fixed, marks)
                            wp.atomic_add(frag, FRAG_FALLBACKS, wp.int64(1))
                if lane < n_park:
                    park(4, lane, float(code))
                sync()
                # runs: a parked slot whose left neighbour has another corner node starts one
                first = 0
                if code >= 0:
                    if lane == 0:
                        first = 1
                    elif int(park(5, lane - 1, 0.0)) != code:
                        first = 1
                packed = runs(1, first, 0, lane, block)
                if first != 0:
                    runs(2, packed >> 16, lane, lane, block)
                if lane == 0:
                    wp.atomic_add(frag, FRAG_PIECES + 1 - fresh, wp.int64(packed & 0xFFFF))
                sync()
                for task in range(lane, 9 * (packed & 0xFFFF), block):
                    add_run(pp, runs(3, task // 9, 0, lane, block), n_park, (task % 9) // 3, task % 3)
                sync()  # the parked slots are read before the next round writes them
            for e in range(lane, WIN_NODES, block):
                flush(pp, e, origin, nn, grid_m, grid_mv, grid_fixed)
            for q in range(lane, 27, block):
                mark_window(marks, brick, nb, q)
            sync()  # every read of the window done before the next segment zeroes it
            seg += n_blocks

    return scatter


class BrickP2G:
    """The brick P2G's scratch buffers for one particle count, the particles' order and
    segments, and its launches."""

    def __init__(self, flags: SceneFlags, n: int, device, *, nodes: int):
        """n: particles; nodes: grid nodes an axis (grid_n + 1)."""
        self.n, self.device, self.flags = n, device, flags
        self.block = BLOCK_CUDA if device.is_cuda else 1
        self.sorted = False
        self.nb = -(-nodes // BRICK)
        with wp.ScopedDevice(device):
            # node bricks the last scatter touched (its windows and fallbacks): the next substep
            # clears only those, and the grid update skips the rest (a shot's grid is mostly empty)
            self.marks = wp.ones(self.nb**3, dtype=wp.int32)
            self.keys = wp.empty(2 * n, dtype=wp.int32)  # radix_sort_pairs sorts in double buffers
            self.idx = wp.array(np.tile(np.arange(n, dtype=np.int32), 2))  # slot -> particle
            self.flag = wp.empty(n, dtype=wp.int32)
            self.pos = wp.empty(n, dtype=wp.int32)
            self.start = wp.empty(n + 1, dtype=wp.int32)
            self.n_seg = wp.zeros(1, dtype=wp.int32)
            self.frag = wp.zeros(FRAG_SLOTS, dtype=wp.int64)  # see FRAG_PIECES

    def launch(self, pp: P2GParams, state, cur, materials, grid_m, grid_mv, grid_fixed, sub, *, sort: bool) -> bool:
        """Scatter `cur` onto the grid; sort: re-sort the particles' order and segments first
        (always before the first scatter). Returns whether it sorted: then this substep's G2P
        must store the particles in the new order (`idx`, slot -> particle)."""
        n, dev = self.n, self.device
        fresh = int(sort or not self.sorted)
        if fresh:
            self.sort(pp, state, cur, sub)
        blocks = max(1, min(n, self.nb**3, MAX_BLOCKS))
        scatter = make_brick_scatter(self.flags, bool(pp.deterministic))
        wp.launch(
            scatter,
            dim=blocks * self.block,
            block_dim=self.block,
            device=dev,
            inputs=[
                pp,
                self.keys,
                self.start,
                self.n_seg,
                self.block,
                blocks,
                self.idx,
                cur.x,
                cur.v,
                cur.C,
                cur.tau,
                cur.J,
                cur.alive,
                state.mass,
                state.volume,
                state.material,
                materials,
                grid_m,
                grid_mv,
                grid_fixed,
                self.marks,
                sub,
                fresh,
                self.frag,
            ],
        )
        return bool(fresh)

    def sort(self, pp: P2GParams, state, cur, sub) -> None:
        """Re-sort the particles' order by brick and corner node, and find the segments."""
        n, dev = self.n, self.device
        wp.launch(brick_keys, dim=n, device=dev, inputs=[pp, cur.x, cur.alive, state.mass, self.idx, self.keys, sub])
        wp.utils.radix_sort_pairs(self.keys, self.idx, n)
        wp.launch(seg_flags, dim=n, device=dev, inputs=[self.keys, self.flag, sub])
        wp.utils.array_scan(self.flag, self.pos, inclusive=False)
        wp.launch(
            seg_starts, dim=n, device=dev, inputs=[self.keys, self.flag, self.pos, n, self.start, self.n_seg, sub]
        )
        self.sorted = True

    def nbytes(self) -> int:
        return int(sum(a.capacity for a in (self.keys, self.idx, self.flag, self.pos, self.start, self.marks)))
