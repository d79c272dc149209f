"""The brick P2G (p2g_brick.py) scatters the reference P2G's grid whatever order its
particles are in: freshly sorted, stale (the particles moved across cells since the sort, as
between the sorts at chunk starts), or shuffled. Deterministic mode bit for bit (fixed-point
sums do not depend on the order); fast mode within float rounding. A missed or doubled
particle would change a node by a whole particle's mass."""

import numpy as np
import pytest

from tests.mpm.mpm_helpers import block, concat
from mpmfx.mpm import Solver, SolverConfig, preset
from mpmfx.mpm.p2g_brick import BrickP2G
from mpmfx.mpm.stepper import SubstepDev

GRID = 16


def _scene(deterministic: bool):
    solver = Solver([preset("Water"), preset("Mushy")], SolverConfig(grid_n=GRID, deterministic=deterministic),
                    device="cpu", stepper="device")
    parts = concat(block((0.2, 0.15, 0.2), (0.45, 0.4, 0.6), grid_n=GRID),
                   block((0.5, 0.15, 0.2), (0.8, 0.4, 0.6), grid_n=GRID, material=1))
    rng = np.random.default_rng(3)
    parts.v[:] = rng.normal(0.0, 0.5, parts.v.shape)
    state = solver.init_state(parts)
    sub = SubstepDev()
    sub.dt, sub.damping_factor, sub.affine_keep, sub.active = 1e-4, 1.0, 1.0, 1
    solver._sub.assign([sub])
    return solver, state, rng


def _grid(solver, state, brick=None, *, sort=False) -> np.ndarray:
    solver._phases(state, state.cur, state.nxt, 0.0, device_clock=True, brick=brick, resort=sort)
    if solver.config.deterministic:
        return solver._grid_fixed.numpy().copy()  # on the CPU numpy() is a view
    return np.concatenate([solver._grid_m.numpy()[..., None], solver._grid_mv.numpy()], -1)


@pytest.mark.parametrize("deterministic", [True, False])
def test_brick_p2g_matches_the_reference_in_any_particle_order(deterministic):
    solver, state, rng = _scene(deterministic)
    brick = BrickP2G(solver.flags, state.n, solver.device)
    _grid(solver, state, brick, sort=True)  # sorted by the positions below, then they move
    x = state.cur.x.numpy()
    moved = x + rng.uniform(-1.0, 1.0, x.shape).astype(np.float32) / GRID
    cell = lambda y: np.floor(y * GRID - 0.5)  # noqa: E731 (the stencil's base node)
    assert (cell(moved) != cell(x)).any(axis=1).mean() > 0.5  # most particles left their sorted run
    state.cur.x.assign(moved)
    ref = _grid(solver, state)
    assert ref[..., 0].sum() > 0
    stale = _grid(solver, state, brick)
    shuffled = BrickP2G(solver.flags, state.n, solver.device)
    _grid(solver, state, shuffled, sort=True)  # then the order no longer matches its keys and segments
    shuffled.idx.assign(np.tile(rng.permutation(state.n).astype(np.int32), 2))
    for out in (stale, _grid(solver, state, shuffled), _grid(solver, state, brick, sort=True)):
        if deterministic:
            np.testing.assert_array_equal(out, ref)
        else:
            np.testing.assert_allclose(out, ref, rtol=1e-5, atol=1e-6 * np.abs(ref).max())
