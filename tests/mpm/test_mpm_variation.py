"""Per-particle material variation in the solver (Particles.variation, SceneFlags.varied)."""

import dataclasses

import numpy as np
import pytest

from mpmfx.mpm import Solver, SolverConfig
from mpmfx.mpm.materials import preset
from mpmfx.mpm.variation import VARIED_FIELDS, variation_factors

from .mpm_helpers import block

GRID = 16
E, XI, PHI, COH, RHO = range(len(VARIED_FIELDS))


def _sand_column(mult=None, *, frames=3, material="Granular", varied=None, split=None):
    """A sand (or snow) column collapsing onto the floor; mult: (n, 5) multipliers, or a
    function of the particles' x. Returns (solver, state, reports)."""
    cfg = SolverConfig(grid_n=GRID, damping=0.0)
    p = block((0.35, 0.07, 0.35), (0.6, 0.5, 0.6), grid_n=GRID)
    if callable(mult):
        mult = mult(p.x)
    varied = mult is not None if varied is None else varied
    p = dataclasses.replace(p, variation=mult)
    solver = Solver([preset(material)], cfg, device="cpu", variation=varied)
    state = solver.init_state(p)
    reports = [solver.advance(state, f / 24, (f + 1) / 24) for f in range(frames)]
    return solver, state, reports


def _ones(x):
    return np.ones((len(x), len(VARIED_FIELDS)), np.float32)


def test_unit_multipliers_give_the_unvaried_result_bit_for_bit():
    _, a, ra = _sand_column(None)
    solver, b, rb = _sand_column(_ones)
    assert solver.flags.varied and solver.flags.key.endswith("v")
    oa, ob = a.cur, b.cur
    for name in ("x", "v", "F", "Jp"):
        assert np.array_equal(getattr(oa, name).numpy(), getattr(ob, name).numpy()), name
    assert [r.substeps for r in ra] == [r.substeps for r in rb]
    assert [r.elastic_energy for r in ra] == [r.elastic_energy for r in rb]


def test_friction_and_stiffness_factors_reach_the_solver():
    """The left half of a column gets weak friction, the right half strong: the left half
    spreads further (and so does a soft half against a stiff one, by its strain)."""

    def half(column, lo, hi):
        def mult(x):
            m = _ones(x)
            left = x[:, 0] < 0.475
            m[left, column], m[~left, column] = lo, hi
            return m

        return mult

    solver, state, _ = _sand_column(half(PHI, 0.3, 1.5), frames=4)
    x = solver.state_to_numpy(state)["x"]
    x0 = _sand_column(None, frames=0)[1].cur.x.numpy()
    left = x0[:, 0] < 0.475
    drift_left = x0[left, 0].mean() - x[left, 0].mean()  # toward -x
    drift_right = x[~left, 0].mean() - x0[~left, 0].mean()  # toward +x
    assert drift_left > 1.5 * max(drift_right, 1e-4), (drift_left, drift_right)  # ~2x at 4 frames

    solver, state, _ = _sand_column(half(E, 0.1, 1.0), frames=1, material="Elastic")
    J = solver.state_to_numpy(state)["J"]
    assert abs(1.0 - J[left]).mean() > 3.0 * abs(1.0 - J[~left]).mean()  # the soft half compresses more


def test_density_multiplies_the_mass_and_stiffness_shortens_the_step():
    mult = lambda x: _ones(x) * np.float32([1, 1, 1, 1, 2])  # noqa: E731
    solver, state, _ = _sand_column(mult, frames=0)
    plain, ref, _ = _sand_column(None, frames=0)
    np.testing.assert_allclose(state.mass.numpy(), 2.0 * ref.mass.numpy(), rtol=1e-6)
    stiff = lambda x: _ones(x) * np.float32([4, 1, 1, 1, 1])  # noqa: E731
    solver, state, _ = _sand_column(stiff, frames=0)
    assert solver.wave_speed(state.clock) == pytest.approx(2.0 * plain.wave_speed(ref.clock), rel=1e-6)
    solver, state, rep = _sand_column(stiff, frames=1)
    _, _, rep_plain = _sand_column(None, frames=1)
    assert rep[0].substeps > 1.5 * rep_plain[0].substeps  # the device stepper's CFL sees the stiff particles
    # snow: the particle's factor rides on the hardening the clock tracks, from the first substep
    solver, state, _ = _sand_column(stiff, frames=0, material="Soft")
    plain, ref, _ = _sand_column(None, frames=0, material="Soft")
    assert state.clock.max_hardening == pytest.approx(4.0)
    assert solver.wave_speed(state.clock) == pytest.approx(2.0 * plain.wave_speed(ref.clock), rel=1e-6)
    solver, state, _ = _sand_column(stiff, frames=1, material="Soft")
    assert state.clock.max_hardening >= 4.0


def test_friction_factor_keeps_the_angle_physical():
    """friction_angle's multiplier acts on tan(phi): any factor > 0 keeps phi in (0, 90)."""
    f = np.array([0.1, 1.0, 3.0, 100.0])
    mult = np.ones((4, 5))
    mult[:, PHI] = f
    for fit in ("repose", "plane_strain", "compression"):
        m = preset("Granular", friction_fit=fit)
        alpha = variation_factors(m, mult)[:, 2] * m.dp_alpha
        phi = np.degrees(np.arctan(np.tan(np.radians(m.friction_angle)) * f))
        assert np.all((phi > 0) & (phi < 90))
        if fit != "repose":  # (the repose fit needs phi < 45 for its own Material; its alpha is tan-linear)
            for a, ph in zip(alpha, phi):
                assert a == pytest.approx(dataclasses.replace(m, friction_angle=float(ph)).dp_alpha, rel=1e-5)
        assert variation_factors(m, mult)[1, 2] == pytest.approx(1.0)


def test_a_varied_checkpoint_resumes_bit_identically():
    rng = np.random.default_rng(3)
    mult = lambda x: np.exp(0.3 * rng.standard_normal((len(x), 5))).astype(np.float32)  # noqa: E731
    solver, state, _ = _sand_column(mult, frames=1, material="Soft")
    ckpt = {k: v.copy() for k, v in solver.checkpoint(state, 1 / 24).items()}
    assert "variation" in ckpt
    ref = [solver.advance(state, f / 24, (f + 1) / 24) for f in (1, 2)]
    fresh = Solver([preset("Soft")], solver.config, device="cpu", variation=True)
    resumed, _ = fresh.restore(ckpt)
    got = [fresh.advance(resumed, f / 24, (f + 1) / 24) for f in (1, 2)]
    for name in ("x", "v", "F", "Jp"):
        assert np.array_equal(getattr(resumed.cur, name).numpy(), getattr(state.cur, name).numpy()), name
    assert [r.substeps for r in got] == [r.substeps for r in ref]
    with pytest.raises(ValueError, match="variation"):
        fresh.restore({k: v for k, v in ckpt.items() if k != "variation"})


def test_variation_inputs_are_checked():
    p = block((0.4, 0.4, 0.4), (0.5, 0.5, 0.5), grid_n=GRID)
    with pytest.raises(ValueError, match="variation=True"):
        Solver([preset("Soft")], SolverConfig(grid_n=GRID), device="cpu").init_state(
            dataclasses.replace(p, variation=_ones(p.x))
        )
    varied = Solver([preset("Soft")], SolverConfig(grid_n=GRID), device="cpu", variation=True)
    with pytest.raises(ValueError, match="variation=True"):
        varied.init_state(p)
    bad = _ones(p.x)
    bad[0, 0] = 0.0
    with pytest.raises(ValueError, match="multipliers > 0"):
        varied.init_state(dataclasses.replace(p, variation=bad))
