"""The brick P2G (p2g_brick.py) scatters the reference P2G's grid whatever order its
particles are in: freshly sorted, stale (the particles moved across cells since the sort, as
between the sorts at chunk starts), or shuffled, within float rounding in both modes (the
deterministic one rounds each run's sums to fixed point, the reference each particle's
contributions). A missed or doubled particle would change a node by a whole particle's mass."""

import numpy as np
import pytest

from mpmfx.mpm import Particles, Solver, SolverConfig, preset
from mpmfx.mpm.p2g_brick import BrickP2G
from mpmfx.mpm.stepper import SubstepDev
from tests.mpm.mpm_helpers import block, concat

GRID = 16


def _set_substep(solver):
    """The device clock's substep (dt 1e-4 s) that _phases(device_clock=True) reads."""
    sub = SubstepDev()
    sub.dt, sub.damping_factor, sub.affine_keep, sub.active = 1e-4, 1.0, 1.0, 1
    solver._sub.assign([sub])


def _scene(deterministic: bool):
    solver = Solver(
        [preset("Water"), preset("Mushy")],
        SolverConfig(grid_n=GRID, deterministic=deterministic),
        device="cpu",
        stepper="device",
    )
    parts = concat(
        block((0.2, 0.15, 0.2), (0.45, 0.4, 0.6), grid_n=GRID),
        block((0.5, 0.15, 0.2), (0.8, 0.4, 0.6), grid_n=GRID, material=1),
    )
    rng = np.random.default_rng(3)
    parts.v[:] = rng.normal(0.0, 0.5, parts.v.shape)
    state = solver.init_state(parts)
    _set_substep(solver)
    return solver, state, rng


def _grid(solver, state, brick=None, *, sort=False, keep_grid=True) -> np.ndarray:
    """One substep's phases; the grid P2G scattered (keep_grid: else the brick path's update
    zeroes it as it reads it, and this returns zeros)."""
    solver._phases(
        state,
        state.cur,
        state.nxt,
        0.0,
        device_clock=True,
        brick=brick,
        resort=sort,
        chunk_start=sort,
        keep_grid=keep_grid,
    )
    if solver.config.deterministic:
        return solver._grid_fixed.numpy().copy()  # on the CPU numpy() is a view
    return np.concatenate([solver._grid_m.numpy()[..., None], solver._grid_mv.numpy()], -1)


@pytest.mark.parametrize("deterministic", [True, False])
def test_brick_p2g_matches_the_reference_in_any_particle_order(deterministic):
    solver, state, rng = _scene(deterministic)
    brick = BrickP2G(solver.flags, state.n, solver.device, nodes=GRID + 1)
    _grid(solver, state, brick, sort=True)  # sorted by the positions below, then they move
    x = state.cur.x.numpy()
    moved = x + rng.uniform(-1.0, 1.0, x.shape).astype(np.float32) / GRID
    cell = lambda y: np.floor(y * GRID - 0.5)  # noqa: E731 (the stencil's base node)
    assert (cell(moved) != cell(x)).any(axis=1).mean() > 0.5  # most particles left their sorted run
    state.cur.x.assign(moved)
    ref = _grid(solver, state)
    assert ref[..., 0].sum() > 0
    stale = _grid(solver, state, brick)
    shuffled = BrickP2G(solver.flags, state.n, solver.device, nodes=GRID + 1)
    _grid(solver, state, shuffled, sort=True)  # then the order no longer matches its keys and segments
    shuffled.idx.assign(np.tile(rng.permutation(state.n).astype(np.int32), 2))
    for out in (stale, _grid(solver, state, shuffled), _grid(solver, state, brick, sort=True)):
        _assert_close(out, ref)


def _assert_close(out, ref):
    """Within float rounding of the reference (fixed point or float grids)."""
    out, ref = out.astype(np.float64), ref.astype(np.float64)
    np.testing.assert_allclose(out, ref, rtol=1e-5, atol=1e-6 * np.abs(ref).max())


SPARSE_GRID = 64


def _sparse_scene(deterministic=True, wall_layer=0.0):
    """A few hundred particles strewn through the domain: most bricks' neighbours are empty,
    so a window's marks are all that covers the nodes its particles reach."""
    solver = Solver(
        [preset("Water"), preset("Mushy")],
        SolverConfig(grid_n=SPARSE_GRID, deterministic=deterministic, wall_layer=wall_layer),
        device="cpu",
        stepper="device",
    )
    rng = np.random.default_rng(5)
    n = 100
    parts = Particles(
        x=rng.uniform(0.15, 0.85, (n, 3)).astype(np.float32),
        v=rng.normal(0.0, 0.5, (n, 3)).astype(np.float32),
        volume=np.full(n, SPARSE_GRID**-3.0 / 8, np.float32),
        material=(np.arange(n) % 2).astype(np.int32),
        body=np.zeros(n, np.int32),
    )
    state = solver.init_state(parts)
    _set_substep(solver)
    return solver, state, rng


@pytest.mark.parametrize(
    "keep_grid, deterministic, wall_layer",
    [(True, True, 0.0), (False, True, 0.0), (False, False, 0.0), (False, True, 0.2)],
)
def test_substeps_after_the_first_clear_and_update_only_the_marked_node_bricks(keep_grid, deterministic, wall_layer):
    """Inside a chunk the brick P2G's node marks stand in for the whole grid: the clear zeroes
    only the bricks the last scatter touched and the grid update skips the rest. The marks
    must cover every node holding mass (the windows' and the fallbacks', for particles that
    left their window since the sort), and G2P must read the same velocities as with the
    dense phases, or particles would pick up the last substep's stale grid. Without keep_grid
    the grid update itself zeroes what it read (no clear launch): then the particles of the
    second substep after the fallback tell whether it left anything behind. With the walls'
    friction over a layer (wall_layer) a node's update reads its column's nodes, so none is
    zeroed while read: the grid is kept and cleared by the marks, with the same particles."""
    solver, state, rng = _sparse_scene(deterministic, wall_layer)
    brick = BrickP2G(solver.flags, state.n, solver.device, nodes=SPARSE_GRID + 1)
    _grid(solver, state, brick, sort=True)  # a chunk's first substep: all of the grid cleared
    x0 = state.cur.x.numpy().copy()
    ref_solver, ref_state, _ = _sparse_scene(deterministic, wall_layer)  # the dense phases at the same positions
    # moved within their windows (up to a cell), then out of them (up to 6 cells): the fallback
    for reach, substeps in ((1.0, 1), (6.0, 2)):
        x = x0 + rng.uniform(-reach, reach, x0.shape).astype(np.float32) / SPARSE_GRID
        state.cur.x.assign(x)
        ref_state.cur.x.assign(x)
        ref = _grid(ref_solver, ref_state)
        for _ in range(substeps):  # each cleared by the last one's marks
            grid = _grid(solver, state, brick, keep_grid=keep_grid)
            if keep_grid or wall_layer > 0:
                _assert_close(grid, ref)
            else:
                assert not grid.any()  # zeroed once read
            for k, a in zip("xvC", (ref_state.nxt.x, ref_state.nxt.v, ref_state.nxt.C)):
                b = getattr(state.nxt, k).numpy()  # (C: row planes, compared as stored)
                np.testing.assert_allclose(b, a.numpy(), rtol=1e-5, atol=1e-5 * np.abs(a.numpy()).max(), err_msg=k)
    marks = brick.marks.numpy().reshape((brick.nb,) * 3)
    assert 0 < marks.sum() < marks.size // 2  # sparse: most bricks are left out


def test_travel_cadence_keeps_the_fastest_particle_inside_its_window():
    from mpmfx.mpm.bricks import SORT_TRAVEL, travel_cadence

    dx, dt = 1.0 / 256, 5e-5
    assert travel_cadence(0.0, dt, dx, 32) == 32  # at rest: once a chunk
    for cells in (0.001, 0.016, 0.03, 0.059, 0.1, 0.2, 1.5):
        k = travel_cadence(cells * dx / dt, dt, dx, 32)
        assert k & (k - 1) == 0 and 1 <= k <= 32  # a power of two: few captured graphs
        assert k * cells <= SORT_TRAVEL or k == 1  # never further than SORT_TRAVEL between sorts...
        assert 2 * k * cells > SORT_TRAVEL or k == 32  # ...nor sorting twice as often as that needs


def _frag(every, fresh_pieces, growth, fallbacks=0.0, chunk=32):
    """The counts a chunk of `chunk` substeps sorted every `every` would leave in BrickP2G.frag
    if its pieces grew by `growth` a substep after each sort."""
    fresh, stale = chunk // every, chunk - chunk // every
    stale_pieces = sum(fresh_pieces + growth * age for age in range(1, every)) * fresh
    return np.array([fresh_pieces * fresh, stale_pieces, fallbacks * stale, fresh, stale], np.int64)


def test_sort_cadence_balances_the_sort_against_the_wear_it_removes():
    """k = sqrt(2 S / g): the cadence whose sorts cost what the runs' wear would (S a sort in
    pieces, g the pieces gained a substep). The figures are hero_dam's and hero_castle's on an
    H200 (lab/cadence_fit.py), where the measured optimum is 4 and 8."""
    from mpmfx.mpm.bricks import SORT_PIECES_FIXED, SORT_PIECES_PER_PARTICLE, sort_cadence

    n = 3_400_000
    S = SORT_PIECES_PER_PARTICLE * n + SORT_PIECES_FIXED
    assert sort_cadence(_frag(4, 487_000, 110_000), 4, n, 32) == 4  # hero_dam
    assert sort_cadence(_frag(8, 360_000, 20_500), 8, 2_640_000, 32) == 8  # hero_castle
    for g in (1e3, 1e4, 1e5, 1e6, 1e7):
        for every in (2, 4, 8, 16):
            k = sort_cadence(_frag(every, 500_000, g), every, n, 32)
            assert k & (k - 1) == 0 and 1 <= k <= 32
            best = np.sqrt(2 * S / g)
            assert k == 32 or k == 1 or best / np.sqrt(2) <= k <= best * np.sqrt(2)  # nearest power of two
    assert sort_cadence(_frag(4, 500_000, 1e3), 4, n, 8) == 8  # never past the travel cap
    assert sort_cadence(_frag(4, 500_000, 0.0), 4, n, 32) == 32  # no wear: once a chunk
    assert sort_cadence(_frag(1, 500_000, 0.0), 1, n, 32) == 2  # no worn substeps seen: try twice as long
    # particles out of their windows wear the order too (each a slow, direct scatter)
    assert sort_cadence(_frag(8, 500_000, 0.0, fallbacks=40_000), 8, n, 32) < 8


def test_the_brick_scatter_counts_the_wear_of_the_order():
    """BrickP2G.frag, what sort_cadence reads: the runs scattered right after a sort and
    later, the particles that left their window (scattered directly), the substeps of each kind."""
    from mpmfx.mpm.bricks import FRAG_FALLBACKS, FRAG_PIECES, FRAG_SUBSTEPS

    solver, state, rng = _scene(False)
    brick = BrickP2G(solver.flags, state.n, solver.device, nodes=GRID + 1)
    brick.frag.zero_()
    _grid(solver, state, brick, sort=True)
    x = state.cur.x.numpy()
    moved = x + rng.uniform(-3.0, 3.0, x.shape).astype(np.float32) / GRID  # some leave their window
    state.cur.x.assign(np.clip(moved, 1.0 / GRID, 1.0 - 1.0 / GRID))  # where G2P keeps them
    for _ in range(3):
        _grid(solver, state, brick)
    frag = brick.frag.numpy()
    assert frag[FRAG_SUBSTEPS] == 1 and frag[FRAG_SUBSTEPS + 1] == 3
    assert frag[FRAG_PIECES] == state.n  # on the CPU a block parks one particle at a time: a run each
    assert 0 < frag[FRAG_FALLBACKS] < 3 * state.n
    assert frag[FRAG_PIECES + 1] + frag[FRAG_FALLBACKS] == 3 * state.n  # each particle in a run or fallen back


def test_the_brick_update_shares_the_walls_friction_over_the_layer_as_the_dense_one_does():
    """A block sliding into the floor: the update over the marked node bricks reads each node's
    column across the wall as the dense update does, so the particles leave with the same
    velocities, which the layer's friction has changed."""
    out = {}
    for layer in (0.0, 0.2):
        cfg = SolverConfig(grid_n=GRID, wall_layer=layer)
        solver = Solver([preset("Water")], cfg, device="cpu", stepper="device")
        floor = cfg.wall_planes[0]
        state = solver.init_state(block((0.3, floor, 0.3), (0.6, floor + 0.3, 0.6), grid_n=GRID, v=(1.0, -1.0, 0.3)))
        _set_substep(solver)
        by_place = lambda: state.nxt.v.numpy()[np.lexsort(state.nxt.x.numpy().T)]  # noqa: E731 (the sort reorders)
        _grid(solver, state)
        out[layer] = by_place().copy()
        brick = BrickP2G(solver.flags, state.n, solver.device, nodes=GRID + 1)
        _grid(solver, state, brick, sort=True, keep_grid=False)
        np.testing.assert_allclose(by_place(), out[layer], rtol=1e-5, atol=1e-6)
    assert np.abs(out[0.2] - out[0.0]).max() > 0.01  # the layer took more than rounding off
