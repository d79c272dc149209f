"""The FLIP/APIC blend (SolverConfig.flip): less damping than APIC, the same step as the numpy
reference, bit-identical replays and resumes, and a refused out-of-range value (CPU)."""

import numpy as np
import pytest

from mpmfx.bench.oscillation import bar, slosh
from mpmfx.bench.reference_step import ReferenceSolver
from mpmfx.mpm import Solver, SolverConfig, preset
from mpmfx.mpm.config import SolverConfigError
from tests.mpm.mpm_helpers import block, concat

FLIP = 0.95  # one share for the whole file: each share compiles kernels of its own


def test_flip_keeps_a_vibration_that_apic_damps():
    apic, flip = bar(20, 0.0), bar(20, FLIP)
    assert apic["decay_per_period"] > 0.002  # APIC loses amplitude here, so the comparison means something
    assert flip["decay_per_period"] < 0.5 * apic["decay_per_period"], (apic, flip)
    assert abs(flip["period_error"]) < 0.02  # the same bar: rod theory's period


def test_flip_keeps_a_water_wave_that_apic_damps():
    apic, flip = slosh(16, 0.0, periods=1.5), slosh(16, FLIP, periods=1.5)
    assert apic["decay_per_period"] > 0.2  # 4 cells deep: APIC loses much of the wave each period
    assert flip["decay_per_period"] < 0.6 * apic["decay_per_period"], (apic, flip)
    assert abs(flip["period_error"]) < 0.03  # linear theory's period


def _splash(engine: str, flip: float, steps: int = 40, dt: float = 1e-3) -> dict:
    """A water block thrown at the floor and a side wall: contact, pressure and gravity."""
    cfg = SolverConfig(grid_n=16, flip=flip, deterministic=False, wall_friction=0.3)
    parts = block((0.3, 0.25, 0.35), (0.55, 0.5, 0.6), grid_n=16, v=(-2.0, -2.5, 0.0))
    if engine == "reference":
        ref = ReferenceSolver([preset("Water")], cfg)
        state = ref.init_state(parts)
        for _ in range(steps):
            ref.step(state, dt)
        return state
    solver = Solver([preset("Water")], cfg, device="cpu")
    state = solver.init_state(parts)
    for _ in range(steps):
        solver.step(state, dt)
    return solver.state_to_numpy(state)


def test_flip_is_the_same_step_as_the_numpy_reference():
    warp, ref = _splash("warp", FLIP), _splash("reference", FLIP)
    np.testing.assert_allclose(warp["x"], ref["x"], atol=2e-5)
    np.testing.assert_allclose(warp["v"], ref["v"], atol=2e-3)
    apic = _splash("warp", 0.0)
    assert np.abs(apic["v"] - warp["v"]).max() > 0.1  # the blend changed the answer, well past the tolerance


def _drop(solver):
    return solver.init_state(block((0.3, 0.2, 0.3), (0.6, 0.45, 0.6), grid_n=16, v=(0.5, -3.0, 0.2)))


def test_flip_replays_and_resumes_bit_identically():
    cfg = SolverConfig(grid_n=16, flip=FLIP, deterministic=True)
    runs = []
    for stepper in ("device", "device", "host"):
        solver = Solver([preset("Water")], cfg, device="cpu", stepper=stepper)
        state = _drop(solver)
        solver.advance(state, 0.0, 1 / 24)
        ckpt = {k: v.copy() for k, v in solver.checkpoint(state, 1 / 24).items()}
        solver.advance(state, 1 / 24, 2 / 24)
        runs.append((solver.state_to_numpy(state), ckpt))
    fresh = Solver([preset("Water")], cfg, device="cpu")
    resumed, t = fresh.restore(runs[0][1])
    fresh.advance(resumed, t, 2 / 24)
    resumed = fresh.state_to_numpy(resumed)
    for key in ("x", "v", "C", "J"):
        for other in (runs[1][0], runs[2][0], resumed):  # a replay, the host stepper, a resume
            assert np.array_equal(runs[0][0][key], other[key]), key


def test_flip_with_one_field_per_body_keeps_fixed_point_and_float_runs_together():
    """Multi-field contact keeps the mass gradients in fixed-point channels too: the blend's
    momentum has channels of its own, so the deterministic run stays the float run's rounding."""
    out = []
    for det in (True, False):
        cfg = SolverConfig(grid_n=16, flip=FLIP, deterministic=det, multi_field=True, gravity=(0.0, 0.0, 0.0))
        solver = Solver([preset("Water")], cfg, device="cpu")
        a = block((0.25, 0.4, 0.4), (0.45, 0.6, 0.6), grid_n=16, body=0, v=(2.0, 0.0, 0.0))
        b = block((0.55, 0.4, 0.4), (0.75, 0.6, 0.6), grid_n=16, body=1, v=(-2.0, 0.0, 0.0))
        state = solver.init_state(concat(a, b))
        solver.advance(state, 0.0, 0.06)
        out.append(solver.state_to_numpy(state))
    assert np.abs(out[0]["v"][:, 0]).mean() < 1.9  # they have met: the contact slowed them
    np.testing.assert_allclose(out[0]["x"], out[1]["x"], atol=1e-4)
    np.testing.assert_allclose(out[0]["v"], out[1]["v"], atol=2e-2)


def test_the_brick_scatter_refuses_a_flip_scene():
    solver = Solver([preset("Water")], SolverConfig(grid_n=16, flip=FLIP), device="cpu")
    assert solver._device_advance.p2g == "reference"  # chosen for a FLIP scene on any device
    solver._device_advance.p2g = "brick"  # (forced, as the GPU measurements do)
    with pytest.raises(ValueError, match="brick P2G has no FLIP blend"):
        solver.advance(_drop(solver), 0.0, 0.01)


@pytest.mark.parametrize("flip", [-0.1, 1.5, float("nan")])
def test_a_flip_share_outside_0_1_is_refused_naming_the_field(flip):
    with pytest.raises(SolverConfigError, match="SolverConfig.flip"):
        SolverConfig(flip=flip)
