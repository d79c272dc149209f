"""Particles that enter during the run (mpm/emission.py): dormant until their birth, then in
the simulation with their own position and velocity; the same with the host loop, the device
stepper and its brick P2G; removed ones never come back; a checkpoint resumes bit-identically."""

import numpy as np
import pytest

from mpmfx.mpm import Solver, SolverConfig, preset
from mpmfx.mpm.emission import device_bytes
from tests.mpm.mpm_helpers import block, concat

FPS = 24.0


def _parts():
    """A water block at rest, and a second block entering at 2.5 frames, falling at 1 domain/s."""
    now = block((0.2, 0.1, 0.2), (0.5, 0.3, 0.8), grid_n=16)
    late = block((0.6, 0.5, 0.3), (0.8, 0.7, 0.7), grid_n=16, body=1, v=(0.0, -1.0, 0.0))
    parts = concat(now, late)
    parts.birth = np.r_[np.zeros(len(now.x)), np.full(len(late.x), 2.5 / FPS)].astype(np.float32)
    return parts, len(now.x)


def _solver(stepper="device", p2g="reference", **cfg):
    solver = Solver([preset("Water")], SolverConfig(grid_n=16, **cfg), device="cpu", stepper=stepper)
    solver._device_advance.p2g = p2g
    return solver


def _run(solver, frames, parts=None):
    parts = parts or _parts()[0]
    state = solver.init_state(parts)

    def copy():  # on the CPU device the host arrays view the solver's memory
        return {k: np.array(a) for k, a in solver.state_to_numpy(state).items()}

    out = [copy()]
    for f in range(frames):
        solver.advance(state, f / FPS, (f + 1) / FPS)
        out.append(copy())
    return out, state


def test_a_late_block_is_dormant_until_its_birth_then_falls_with_its_velocity():
    parts, n0 = _parts()
    frames, _ = _run(_solver(), 4, parts)
    for f, s in enumerate(frames):
        alive = s["alive"][n0:]
        if f <= 2:  # born at 2.5 frames: dormant, unmoved, at its emitted velocity
            assert not alive.any()
            np.testing.assert_array_equal(s["x"][n0:], parts.x[n0:])
        else:
            assert alive.all()
    assert frames[4]["x"][n0:, 1].mean() < parts.x[n0:, 1].mean() - 0.02  # it falls once born
    assert frames[4]["alive"][:n0].all()


@pytest.mark.parametrize("stepper, p2g", [("device", "reference"), ("device", "brick")])
def test_the_device_stepper_wakes_particles_as_the_host_loop_does(stepper, p2g):
    ref, _ = _run(_solver("host"), 4)
    out, _ = _run(_solver(stepper, p2g), 4)
    for a, b in zip(ref, out):
        np.testing.assert_array_equal(a["alive"], b["alive"])
        if p2g == "reference":
            np.testing.assert_array_equal(a["x"], b["x"])
        else:  # the brick P2G sums in another order (test_mpm_stepper.py): close, not equal
            np.testing.assert_allclose(a["x"], b["x"], rtol=0, atol=1e-4)


@pytest.mark.parametrize("p2g", ["reference", "brick"])
def test_a_resumed_run_wakes_the_same_particles_bit_identically(p2g):
    whole, _ = _run(_solver(p2g=p2g), 4)
    solver = _solver(p2g=p2g)
    state = solver.init_state(_parts()[0])
    for f in range(2):
        solver.advance(state, f / FPS, (f + 1) / FPS)
    ckpt = solver.checkpoint(state, 2 / FPS)
    assert "birth" in ckpt
    resumed = _solver(p2g=p2g)
    state2, t = resumed.restore(ckpt)
    for f in (2, 3):
        resumed.advance(state2, f / FPS, (f + 1) / FPS)
    for k, a in resumed.state_to_numpy(state2).items():
        np.testing.assert_array_equal(a, whole[4][k], err_msg=k)


def test_a_removed_particle_never_comes_back():
    """A particle removed at the domain edge (REMOVE mode: alive = 0, as a dormant one) stays
    gone though its birth time is past: waking marks a particle born."""
    parts, n0 = _parts()
    solver = _solver()
    state = solver.init_state(parts)
    for f in range(3):
        solver.advance(state, f / FPS, (f + 1) / FPS)
    assert np.isinf(state.birth.numpy()).all()  # every particle born, none pending
    alive = state.cur.alive.numpy()
    alive[n0::2] = 0  # as G2P's keep_in_domain does in REMOVE mode
    state.cur.alive.assign(alive)
    solver.advance(state, 3 / FPS, 4 / FPS)
    np.testing.assert_array_equal(state.cur.alive.numpy(), alive)


def test_a_scene_without_births_has_no_birth_array():
    solver = _solver()
    state = solver.init_state(block((0.2, 0.1, 0.2), (0.5, 0.3, 0.8), grid_n=16))
    assert state.birth is None and "birth" not in solver.checkpoint(state, 0.0)


@pytest.mark.parametrize("material", ["Water", "Mushy"])
def test_the_memory_estimate_is_what_the_state_and_grid_take(material):
    """device_bytes against the arrays a CPU run allocates (no brick P2G there: gpu=False)."""
    solver = Solver([preset(material)], SolverConfig(grid_n=16), device="cpu")
    state = solver.init_state(_parts()[0])
    arrays = [*state.cur.arrays(), *state.nxt.arrays(), *state.consts(), state.birth]
    arrays += [solver._grid_m, solver._grid_mv, solver._grid_normal, solver._grid_fixed, solver._grid_v]
    real = sum(a.capacity for a in arrays)
    est = device_bytes(state.n, solver.flags, 16, deterministic=True, births=True, gpu=False)
    assert est == pytest.approx(real, rel=0.01)
