"""Bricks of grid nodes (BRICK^3 nodes each) and the particles' order by brick, for the brick
P2G (p2g_brick.py): the sort keys (brick, then corner node inside it) and the segments of equal
bricks, the node marks that keep the clear and the grid update to the bricks a scatter touched,
and the cadence of the re-sorts (travel_cadence, sort_cadence).
"""

from __future__ import annotations

import math

import warp as wp

from .p2g import P2GParams
from .stepper import SubstepDev

__all__ = ["BRICK", "fits_brick_keys", "sort_cadence", "travel_cadence"]

BRICK = 4  # corner nodes per brick and axis (a key's low 6 bits)
SORT_TRAVEL = 1.0  # cells the fastest particle may move between two sorts: a window's slack (travel_cadence)
SORT_PIECES_PER_PARTICLE = 0.32  # a sort's cost in scattered pieces (sort_cadence; fitted
SORT_PIECES_FIXED = 2.5e5  # to the measured time of a sort with its G2P's moves against a piece's)
FALLBACK_PIECES = 16.0  # a particle out of its window, in pieces: a guess, not fitted (no measured scene fell
# back; travel_cadence keeps particles inside their windows, so it rarely matters)
NO_KEY = wp.constant(0x7FFFFFFF)  # tracers and removed particles: sorted last, never scattered
# BrickP2G.frag, int64 counters the scatter adds to (sort_cadence reads them): the runs it
# scattered right after a sort [0] and later [1], the fallback particles (out of their
# window) [2], and the substeps of each kind [3], [4]
FRAG_PIECES = wp.constant(0)
FRAG_FALLBACKS = wp.constant(2)
FRAG_SUBSTEPS = wp.constant(3)
FRAG_SLOTS = 5


def fits_brick_keys(nodes: int) -> bool:
    """Whether a grid of `nodes` per axis keeps the sort keys (brick * 64 + corner) in int32."""
    return (-(-nodes // BRICK)) ** 3 * 64 < NO_KEY


def travel_cadence(speed: float, dt: float, dx: float, longest: int) -> int:
    """The most substeps between two sorts (a power of two up to `longest`) in which a particle
    at `speed` (domain/s, the last substep's fastest; dt in s, dx a cell in domain units) moves
    at most SORT_TRAVEL cells: further, and it could leave its brick's window (one cell of slack)
    and add to the grid directly, the slow path."""
    travel = speed * dt / dx
    k = 1
    while 2 * k <= longest and 2 * k * travel <= SORT_TRAVEL:
        k *= 2
    return k


def sort_cadence(frag, every: int, n: int, cap: int) -> int:
    """Substeps between the next chunk's sorts of the particles' order, from the wear the last
    chunk's scatters counted (`frag`, BrickP2G.frag, with the last chunk sorted every `every`
    substeps); n particles; cap: the most allowed (travel_cadence, at most a chunk).

    Why: between sorts the particles cross cell faces, a run (consecutive slots sharing a corner
    node) breaks into pieces, and the scatter spends a task on each piece; a sort costs what
    SORT_PIECES_PER_PARTICLE * n + SORT_PIECES_FIXED pieces cost. If the pieces grow by g a
    substep after a sort, sorting every k substeps costs S / k + g (k - 1) / 2 a substep, least at
    k = sqrt(2 S / g) (rounded to a power of two in log scale). g is measured: the mean pieces of
    the substeps after the first of each sort, against those right after a sort. With no such
    substeps (every substep sorted) the next chunk tries twice the cadence. The counts are of
    particles, not of time, so a deterministic run picks the same cadences when replayed.

    The rule's pick is at or next to the fastest fixed cadence on the shipped GPU shots
    (lab/cadence_fit.py measures the cadences and fits the sort's cost). A
    falling block's runs heal as it falls on (a whole run crosses a face and is one run again),
    which the linear growth does not see, so it sorts more often there than it needs to."""
    fresh_sub, stale_sub = float(frag[FRAG_SUBSTEPS]), float(frag[FRAG_SUBSTEPS + 1])
    if fresh_sub == 0:
        return max(1, min(every, cap))
    if stale_sub == 0:
        return max(1, min(2 * every, cap))
    wear = float(frag[FRAG_PIECES + 1]) / stale_sub - float(frag[FRAG_PIECES]) / fresh_sub
    wear += FALLBACK_PIECES * float(frag[FRAG_FALLBACKS]) / stale_sub
    if wear <= 0.0:
        return cap
    growth = wear / (0.5 * every)  # stale substeps are 1 .. every-1 after their sort: on average every / 2
    k = math.sqrt(2.0 * (SORT_PIECES_PER_PARTICLE * n + SORT_PIECES_FIXED) / growth)
    return int(max(1, min(cap, 2 ** round(math.log2(max(k, 1.0))))))


@wp.func
def base_node(xp: wp.vec3, inv_dx: float) -> wp.vec3i:
    """The corner node of a particle's stencil, as the reference P2G computes it."""
    xg = xp * inv_dx
    return wp.vec3i(int(wp.floor(xg[0] - 0.5)), int(wp.floor(xg[1] - 0.5)), int(wp.floor(xg[2] - 0.5)))


@wp.func
def node_brick(i: int, j: int, k: int, nb: int) -> int:
    """The brick (BRICK^3 nodes, nb a grid axis) holding grid node (i, j, k): the unit of the
    node marks that keep the clear and the grid update to the nodes a scatter touched."""
    return ((i // BRICK) * nb + j // BRICK) * nb + k // BRICK


@wp.func
def marked_node(marks: wp.array(dtype=wp.int32), t: int, nb: int, nodes: int) -> wp.vec3i:
    """The node of thread t of a launch of BRICK^3 threads a node brick (`marks` order), or
    (-1, -1, -1) where its brick is unmarked or it lies past the last node. A brick's threads
    share one mark, so a warp leaves an empty brick at once."""
    b = t // (BRICK * BRICK * BRICK)
    if marks[b] == 0:
        return wp.vec3i(-1)
    q = t % (BRICK * BRICK * BRICK)
    node = wp.vec3i(
        (b // (nb * nb)) * BRICK + q // (BRICK * BRICK),
        ((b // nb) % nb) * BRICK + (q // BRICK) % BRICK,
        (b % nb) * BRICK + q % BRICK,
    )
    if wp.max(node) >= nodes:
        return wp.vec3i(-1)
    return node


@wp.kernel(enable_backward=False)
def brick_keys(
    pp: P2GParams,
    x: wp.array(dtype=wp.vec3),
    alive: wp.array(dtype=wp.int32),
    mass: wp.array(dtype=float),
    idx: wp.array(dtype=wp.int32),
    keys: wp.array(dtype=wp.int32),
    sub: wp.array(dtype=SubstepDev),
):
    p = wp.tid()
    if sub[0].active == 0:
        return
    # the sort starts from the storage order, so equal keys keep it: the order inside a run, and
    # so a run's float sums, depend on the run's history, which a checkpoint keeps (State.pid: a
    # resumed run's slots are the first run's, and it sums as the first did)
    idx[p] = p
    if alive[p] == 0 or mass[p] == 0.0:
        keys[p] = NO_KEY
        return
    b = wp.max(base_node(x[p], pp.inv_dx), wp.vec3i(0))  # >= 0 inside the domain; keys stay non-negative
    brick = node_brick(b[0], b[1], b[2], (pp.nodes + BRICK - 1) // BRICK)
    keys[p] = brick * 64 + ((b[0] % BRICK) * BRICK + b[1] % BRICK) * BRICK + b[2] % BRICK


@wp.kernel(enable_backward=False)
def seg_flags(keys: wp.array(dtype=wp.int32), flag: wp.array(dtype=wp.int32), sub: wp.array(dtype=SubstepDev)):
    s = wp.tid()
    if sub[0].active == 0:
        return
    k = keys[s]
    f = int(0)
    if k != NO_KEY and (s == 0 or keys[s - 1] // 64 != k // 64):
        f = 1
    flag[s] = f


@wp.kernel(enable_backward=False)
def seg_starts(
    keys: wp.array(dtype=wp.int32),
    flag: wp.array(dtype=wp.int32),
    pos: wp.array(dtype=wp.int32),
    n: int,
    start: wp.array(dtype=wp.int32),
    n_seg: wp.array(dtype=wp.int32),
    sub: wp.array(dtype=SubstepDev),
):
    """start[i]: the first slot of segment i; start[n_seg]: one past the last sorted particle
    (the dead ones sort last, NO_KEY)."""
    s = wp.tid()
    if sub[0].active == 0:
        return
    if flag[s] != 0:
        start[pos[s]] = s
    valid = keys[s] != NO_KEY
    if valid and (s == n - 1 or keys[s + 1] == NO_KEY):
        start[pos[s] + flag[s]] = s + 1
        n_seg[0] = pos[s] + flag[s]
    if s == 0 and not valid:
        n_seg[0] = 0
