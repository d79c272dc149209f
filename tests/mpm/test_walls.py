"""The domain walls are planes at SolverConfig.wall_planes: material rests on them, and their
friction is a law that does not depend on the grid (docs/physics.md, "Boundaries")."""

import numpy as np
import pytest

from mpmfx.mpm import Collider, ColliderKind, Particles, Solver, SolverConfig, preset
from tests.mpm.mpm_helpers import block


def test_the_walls_are_the_planes_the_config_declares():
    cfg = SolverConfig(grid_n=32)
    assert cfg.wall_planes == (3 / 32, 29 / 32)  # boundary_cells = 3 cells inside each face


def test_a_block_at_rest_sits_on_the_declared_floor():
    """An elastic block placed on the floor plane stays there: its bottom (the lowest particle
    less the quarter cell it sits above its cell's face) settles within 0.1 dx of the plane,
    neither sinking into the wall nor floating above it."""
    n = 16
    floor, _ = SolverConfig(grid_n=n).wall_planes
    p = block((0.3, floor, 0.3), (0.7, floor + 0.25, 0.7), grid_n=n)
    solver = Solver([preset("Elastic")], SolverConfig(grid_n=n), device="cpu")
    state = solver.init_state(p)
    solver.advance(state, 0.0, 0.3)
    y = solver.state_to_numpy(state)["x"][:, 1]
    bottom = y.min() - 0.25 / n  # ppc = 2: particles sit a quarter cell above their cell's face
    assert abs(bottom - floor) < 0.1 / n


@pytest.mark.parametrize("walls", ["separate", "slip"])
def test_a_pool_at_rest_neither_climbs_nor_enters_the_walls(walls):
    """Water filling the tank wall to wall stays still: the particles next to a side wall rise
    less than half a cell in 0.3 s, no particle goes beyond a wall's plane, and the volume
    ratio J stays above 0.95 (the water does not fall into a gap the walls leave)."""
    n = 16
    dx = 1 / n
    lo, hi = SolverConfig(grid_n=n).wall_planes
    p = block((lo, lo, lo), (hi, lo + 6 * dx, hi), grid_n=n)
    solver = Solver([preset("Water")], SolverConfig(grid_n=n, walls=(walls,) * 6), device="cpu")
    state = solver.init_state(p)
    side = lambda x: (x[:, 0] < lo + dx) | (x[:, 0] > hi - dx)  # noqa: E731
    top = p.x[side(p.x), 1].max()
    climb, j_min = 0.0, 1.0
    for f in range(6):
        solver.advance(state, f * 0.05, (f + 1) * 0.05)
        out = solver.state_to_numpy(state)
        x = out["x"]
        climb = max(climb, x[side(x), 1].max() - top)
        j_min = min(j_min, float(out["J"].min()))
        assert np.all(x >= lo - 0.01 * dx) and np.all(x <= hi + 0.01 * dx)
    assert climb < 0.5 * dx
    assert j_min > 0.95


def _plane(y: float, mu: float) -> Collider:
    return Collider(kind=ColliderKind.PLANE, friction=mu, point=(0.0, y, 0.0), normal=(0.0, 1.0, 0.0))


def test_a_block_at_rest_sits_on_a_collider_plane_through_nodes():
    """A collider's surface holds the nodes on it too: a block on a plane collider that passes
    through a row of nodes rests on it (it sank a tenth of a cell when only the nodes inside
    were held), as it does on a plane between two rows."""
    n = 16
    for y0 in (0.25, 0.25 + 0.5 / n):
        p = block((0.3, y0, 0.3), (0.7, y0 + 0.25, 0.7), grid_n=n)
        solver = Solver([preset("Elastic")], SolverConfig(grid_n=n), colliders=[_plane(y0, 0.5)], device="cpu")
        state = solver.init_state(p)
        solver.advance(state, 0.0, 0.3)
        bottom = solver.state_to_numpy(state)["x"][:, 1].min() - 0.25 / n
        assert abs(bottom - y0) < 0.05 / n, y0


def _slide_deceleration(n: int, mu: float, t: float = 0.06, collider: bool = False) -> float:
    """Mean deceleration of an elastic slab (2 cells thick in z) launched at 1 domain/s along the
    floor (or along a plane collider at y = 0.25 with the walls frictionless), over its first t
    seconds, in units of mu g."""
    dx = 1 / n
    floor = 0.25 if collider else SolverConfig(grid_n=n).wall_planes[0]
    p = block((0.2, floor, 0.5 - dx), (0.45, floor + 0.125, 0.5 + dx), grid_n=n, v=(1.0, 0.0, 0.0))
    cfg = SolverConfig(grid_n=n, wall_friction=0.0 if collider else mu)
    colliders = [_plane(floor, mu)] if collider else []
    solver = Solver([preset("Elastic")], cfg, colliders=colliders, device="cpu")
    state = solver.init_state(p)
    solver.advance(state, 0.0, t)
    out = solver.state_to_numpy(state)
    m = out["mass"].astype(np.float64)
    v = (m * out["v"][:, 0]).sum() / m.sum()
    return (1.0 - v) / t / (mu * -cfg.gravity[1])


def test_wall_friction_decelerates_a_sliding_block_at_mu_g_on_every_grid():
    """Coulomb friction is a law in physical terms: the floor stops the weight's normal speed
    at the nodes on its plane, and takes mu times that impulse off the tangential momentum, so
    a block slides to rest at mu g whatever the cell size (grid 16, 32 and 48)."""
    for n in (16, 32, 48):
        assert _slide_deceleration(n, 0.5) == pytest.approx(1.0, abs=0.05), n


def test_collider_friction_decelerates_a_sliding_block_at_mu_g_on_every_grid():
    for n in (16, 24, 32):
        assert _slide_deceleration(n, 0.5, collider=True) == pytest.approx(1.0, abs=0.05), n


def _water_slide_deceleration(n: int, layer: float, mu: float = 0.3, t: float = 0.2) -> float:
    """Mean deceleration of the centre of mass of a water slab (0.3 long, 0.125 deep, wall to
    wall in z) launched at 1 domain/s along the floor, over its first t seconds, in units of mu g."""
    cfg = SolverConfig(grid_n=n, wall_friction=mu, wall_layer=layer)
    lo, hi = cfg.wall_planes
    dx, sp = 1 / n, 0.5 / n
    axes = [np.arange(0.15 + sp / 2, 0.45, sp), np.arange(lo + sp / 2, lo + 0.125, sp)]
    axes.append(lo + (np.arange(round((hi - lo) / dx)) + 0.5) * dx)  # one particle a cell in z
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)
    k = len(x)
    p = Particles(
        x=x,
        v=np.tile(np.float32([1.0, 0.0, 0.0]), (k, 1)),
        volume=np.full(k, sp * sp * dx, np.float32),
        material=np.zeros(k, np.int32),
        body=np.zeros(k, np.int32),
    )
    solver = Solver([preset("Water")], cfg, device="cpu")
    state = solver.init_state(p)
    solver.advance(state, 0.0, t)
    out = solver.state_to_numpy(state)
    m = out["mass"].astype(np.float64)
    v = (m * out["v"][:, 0]).sum() / m.sum()
    return (1.0 - v) / t / (mu * -cfg.gravity[1])


def test_wall_friction_slows_sliding_water_the_same_on_every_grid():
    """Water has no shear strength, so the floor's friction slows only the water it reaches:
    shared over a layer of fixed thickness (0.1 here, 1.6 to 3.2 cells), the slab's centre of
    mass slows alike at grid 16, 24 and 32 (measured 0.78-0.83 mu g over 0.2 s; the water
    above the layer slides on, so less than mu g). At the walls' nodes only (wall_layer 0) the
    slowed layer thins with the cell, and the slab at grid 32 slows at 0.58 mu g."""
    layered = [_water_slide_deceleration(n, 0.1) for n in (16, 24, 32)]
    assert max(layered) - min(layered) < 0.08, layered
    assert all(0.7 < d < 0.95 for d in layered), layered
    assert _water_slide_deceleration(32, 0.0) < min(layered) - 0.1
