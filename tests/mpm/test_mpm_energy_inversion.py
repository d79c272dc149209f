"""Elastic energy in the report, inverted particles, and F not drifting through the SVD."""

import numpy as np
import pytest

from mpmfx.mpm import PRESETS, Mode, Solver, SolverConfig, preset
from mpmfx.mpm.state import m33_assign
from tests.mpm.mpm_helpers import block, free_bar

ZERO_G = (0.0, 0.0, 0.0)
ALL = list(PRESETS)  # one scene with every mode: the same compiled module as the preset drop test


def _energy_reference(mats, material, volume, F, J, Jp):
    """Energy the models define, in numpy (float64): fixed-corotated with hardened moduli,
    Hencky StVK, Tait potential, tracers 0."""
    total = 0.0
    for k, mid in enumerate(material):
        m = mats[mid]
        sig = np.linalg.svd(F[k].astype(np.float64), compute_uv=False)
        if m.mode == Mode.SNOW:
            h = np.exp(m.hardening * (1.0 - Jp[k]))
            psi = h * (m.mu0 * ((sig - 1) ** 2).sum() + 0.5 * m.lambda0 * (sig.prod() - 1) ** 2)
        elif m.mode == Mode.SAND:
            eps = np.log(sig)
            psi = m.mu0 * (eps**2).sum() + 0.5 * m.lambda0 * eps.sum() ** 2
        elif m.mode == Mode.WATER:
            g, j = m.eos_gamma, float(J[k])
            psi = 0.0 if j >= 1 else m.bulk_modulus * ((j ** (1 - g) - 1) / (g - 1) + (j - 1))
        else:
            psi = 0.0
        total += volume[k] * psi
    return total


def test_elastic_energy_matches_each_model():
    mats = [PRESETS[n] for n in ALL]
    solver = Solver(mats, SolverConfig(grid_n=16), device="cpu")
    rng = np.random.default_rng(3)
    n = 40
    p = block((0.4, 0.4, 0.4), (0.55, 0.55, 0.55), grid_n=16)
    p = type(p)(p.x[:n], p.v[:n], p.volume[:n], np.arange(n, dtype=np.int32) % len(mats), p.body[:n])
    state = solver.init_state(p)
    F = (np.eye(3) + 0.1 * rng.normal(size=(n, 3, 3))).astype(np.float32)
    J = rng.uniform(0.9, 1.05, n).astype(np.float32)
    Jp = np.where([mats[m].mode == Mode.SNOW for m in p.material], rng.uniform(0.9, 1.0, n), 0.0).astype(np.float32)
    m33_assign(state.cur.F, F)
    state.cur.J.assign(J)
    state.cur.Jp.assign(Jp)
    ref = _energy_reference(mats, p.material, p.volume, F, J, Jp)
    assert ref > 0
    assert solver.elastic_energy(state) == pytest.approx(ref, rel=1e-4)


def test_tait_energy_is_the_potential_of_the_pressure():
    """-d(psi)/dJ = p = K (J^-gamma - 1): the energy QA records is the one the forces use."""
    mats = [preset(n) for n in ALL]
    water = ALL.index("Water")
    solver = Solver(mats, SolverConfig(grid_n=16), device="cpu")
    p = block((0.4, 0.4, 0.4), (0.45, 0.45, 0.45), grid_n=16)
    p.material[:] = water
    state = solver.init_state(p)
    m, dJ = mats[water], 1e-3
    for j in (0.9, 0.97):
        e = []
        for jj in (j - dJ, j + dJ):
            state.cur.J.assign(np.full(state.n, jj, np.float32))
            e.append(solver.elastic_energy(state) / p.volume.sum())
        assert -(e[1] - e[0]) / (2 * dJ) == pytest.approx(m.bulk_modulus * (j**-m.eos_gamma - 1), rel=1e-2)


def test_report_energy_is_exchanged_and_conserved_in_a_free_bar():
    """Undamped free bar in its first mode (Buzzi et al. 2008): the report's kinetic and
    elastic energy trade places each quarter period and their sum stays put."""
    solver, state, p, _ = free_bar(grid_n=16, half_width=0.1)
    ke0 = 0.5 * float((state.mass.numpy() * (p.v**2).sum(axis=1)).sum())
    reports = [solver.advance(state, f / 40, (f + 1) / 40) for f in range(12)]  # period 0.12 s
    ee = np.array([r.elastic_energy for r in reports])
    total = np.array([r.kinetic_energy + r.elastic_energy for r in reports])
    assert ee.max() > 0.8 * ke0 and ee.min() < 0.1 * ke0  # all of it goes into strain and back
    np.testing.assert_allclose(total, ke0, rtol=0.1)


@pytest.mark.parametrize("kind", ["every other particle", "all particles"])
def test_inverted_elastic_block_recovers(kind):
    """Inversion must be survivable. Mirrored particles (det F = -1) among normal
    ones would drag the whole block flat (det F -> 0); they are mirrored back out,
    the frame reports it, and the block keeps its volume."""
    p = block((0.4, 0.4, 0.4), (0.6, 0.6, 0.6), grid_n=16)
    solver = Solver([preset("Elastic")], SolverConfig(grid_n=16, gravity=ZERO_G), device="cpu")
    state = solver.init_state(p)
    F = np.tile(np.eye(3, dtype=np.float32), (state.n, 1, 1))
    F[:: 2 if kind.startswith("every") else 1, 0, 0] = -1.0
    m33_assign(state.cur.F, F)
    solver.update_stress(state)
    reports = [solver.advance(state, f / 25, (f + 1) / 25) for f in range(5)]  # 0.2 s
    out = solver.state_to_numpy(state)
    assert reports[0].inverted > 0 and reports[0].j_min <= 0  # QA sees the event
    assert reports[-1].inverted == 0
    assert (out["J"] > 0.5).mean() > 0.95
    width = np.ptp(out["x"], axis=0)
    assert width.min() > 0.8 * np.ptp(p.x, axis=0).min()  # not flattened along any axis
    assert np.all(np.isfinite(out["F"]))


@pytest.mark.parametrize("name", ["Soft", "CohesiveGranular"])
def test_resting_material_keeps_its_stretch(name):
    """A body at rest inside the snow clamp box / the sand cone keeps singular values 1:
    the return map does not rebuild F from its float32 SVD (which shrinks it ~1e-6 per
    call: 2e-5 to 5e-5 over these 600 substeps) when nothing is projected."""
    mats = [preset(n) for n in ALL]
    solver = Solver(mats, SolverConfig(grid_n=16, gravity=ZERO_G), device="cpu")
    p = block((0.4, 0.4, 0.4), (0.5, 0.5, 0.5), grid_n=16, material=ALL.index(name))
    state = solver.init_state(p)
    dt = solver._cfl_dt(state.clock)
    for _ in range(600):
        solver.step(state, dt)
    sig = np.linalg.svd(solver.state_to_numpy(state)["F"].astype(np.float64), compute_uv=False)
    np.testing.assert_allclose(sig, 1.0, atol=2e-6)
