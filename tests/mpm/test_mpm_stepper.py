"""The device stepper (chunks of substeps decided on the device, stepper.py / chunked.py)
against the reference host loop, over a few hundred substeps on the CPU. Deterministic mode,
with the host loop's P2G: bit for bit (the same substeps, rejections and particles). With the
brick P2G of p2g_brick.py (the GPU's), which sums each node's contributions in another order
(fast mode) or rounds each run's sums to fixed point (deterministic mode): the same substeps,
positions within 1e-4 domain units (1/600 of a cell), velocities within 1e-3 domain/s, and in
deterministic mode bit-identical replays and resumes."""

import numpy as np
import pytest

from mpmfx.mpm import SimulationError, Solver, SolverConfig, preset
from tests.mpm.mpm_helpers import block, concat

CASES = {
    # name: (materials, particles, config overrides, frames)
    "water+snow, deterministic": (
        ["Water", "Mushy"],
        lambda: concat(
            block((0.2, 0.15, 0.2), (0.45, 0.4, 0.8), grid_n=16),
            block((0.55, 0.15, 0.2), (0.8, 0.4, 0.8), grid_n=16, material=1),
        ),
        {},
        6,
    ),
    "sand": (["Granular"], lambda: block((0.3, 0.2, 0.3), (0.7, 0.5, 0.7), grid_n=16), {}, 6),
    "water+snow, fast mode": (
        ["Water", "Mushy"],
        lambda: concat(
            block((0.2, 0.15, 0.2), (0.45, 0.4, 0.8), grid_n=16),
            block((0.55, 0.15, 0.2), (0.8, 0.4, 0.8), grid_n=16, material=1),
        ),
        {"deterministic": False},
        6,
    ),
    "rejections": (
        ["Elastic"],
        lambda: block((0.3, 0.2, 0.3), (0.6, 0.45, 0.6), grid_n=16),
        {"cfl": 1.0, "damping": 1.0, "gravity": (0, -4e4, 0)},
        2,
    ),
    # keyframed colliders (posed on the device by the device stepper): a box sweeping and
    # turning through snow, a sphere that stays, time_scale != 1
    "colliders": (["Mushy"], lambda: block((0.25, 0.15, 0.25), (0.75, 0.4, 0.75), grid_n=16), {"time_scale": 0.8}, 5),
}


def _colliders():
    from scipy.spatial.transform import Rotation

    from mpmfx.mpm import Collider, ColliderKind

    quats = Rotation.from_euler("y", [[0], [50], [140]], degrees=True).as_quat().astype(np.float32)
    box = Collider(
        ColliderKind.BOX,
        half_extents=(0.04, 0.12, 0.2),
        friction=0.3,
        times=[0.0, 0.09, 0.2],
        translations=[(0.15, 0.3, 0.5), (0.45, 0.27, 0.5), (0.7, 0.3, 0.45)],
        rotations=quats,
    )
    sphere = Collider(ColliderKind.SPHERE, radius=0.08, translations=[(0.5, 0.2, 0.25)])
    return [box, sphere]


def _solver(stepper, mats, cfg, p2g):
    colliders = _colliders() if "time_scale" in cfg else ()
    solver = Solver(
        [preset(m) for m in mats], SolverConfig(grid_n=16, **cfg), colliders=colliders, device="cpu", stepper=stepper
    )
    if not solver.flags.multi_field:
        solver._device_advance.p2g = p2g
    return solver


def _run(stepper, mats, parts, cfg, frames, *, p2g="brick"):
    """p2g: "brick" (the GPU's default) or "reference" (the CPU's)."""
    solver = _solver(stepper, mats, cfg, p2g)
    state = solver.init_state(parts)
    reports = [solver.advance(state, f / 24, (f + 1) / 24) for f in range(frames)]
    return solver.state_to_numpy(state), reports, state.clock


@pytest.mark.parametrize("case", CASES)
def test_device_stepper_matches_the_host_loop_bit_for_bit(case):
    mats, make, cfg, frames = CASES[case]
    ref, ref_reports, ref_clock = _run("host", mats, make(), cfg, frames)
    # deterministic: the stepper's own logic, with the host loop's P2G; fast: the brick P2G
    # (its deterministic mode rounds per run: test_brick_p2g_deterministic_mode below)
    out, reports, clock = _run(
        "device", mats, make(), cfg, frames, p2g="brick" if cfg.get("deterministic") is False else "reference"
    )
    assert sum(r.substeps for r in reports) >= 50
    if case == "rejections":
        assert sum(r.rejected_substeps for r in reports) > 0
    assert [r.substeps for r in reports] == [r.substeps for r in ref_reports]
    if not cfg.get("deterministic", True):
        np.testing.assert_allclose(out["x"], ref["x"], rtol=0, atol=1e-4)
        np.testing.assert_allclose(out["v"], ref["v"], rtol=0, atol=1e-3)
        return
    for key in ref:
        np.testing.assert_array_equal(out[key], ref[key], err_msg=key)
    assert clock == ref_clock
    for a, b in zip(reports, ref_reports):
        for f in (
            "substeps",
            "rejected_substeps",
            "dt_min",
            "dt_max",
            "max_speed",
            "cfl_used",
            "j_min",
            "j_max",
            "particles_lost",
            "inverted",
            "mass",
            "kinetic_energy",
        ):
            assert getattr(a, f) == getattr(b, f), f
        np.testing.assert_array_equal(a.momentum, b.momentum)


def test_device_stepper_raises_the_host_loops_errors():
    parts = block((0.3, 0.2, 0.3), (0.6, 0.45, 0.6), grid_n=16)
    for cfg, match in (({"max_substeps_per_frame": 3}, "3 substeps did not reach"), ({"dt_min": 5e-3}, "dt_min")):
        msgs = []
        for stepper in ("host", "device"):
            solver = Solver([preset("Soft")], SolverConfig(grid_n=16, **cfg), device="cpu", stepper=stepper)
            state = solver.init_state(parts)
            with pytest.raises(SimulationError, match=match) as err:
                solver.advance(state, 0.0, 1 / 24)
            msgs.append(str(err.value))
        assert msgs[0] == msgs[1]


def test_brick_p2g_deterministic_mode_replays_and_resumes_bit_identically():
    """The brick P2G rounds each run's sums to fixed point, so its deterministic mode is not
    the reference's bits: close to the host loop as fast mode is, and bit-identical with
    itself, run again or resumed from a checkpoint (whatever order the particles were in
    before: a run's order is particle order). On the CPU a block parks one particle at a
    time, so runs are single particles there; lab/p2g_gpu.py checks replay and resume
    with real runs on a GPU."""
    mats, make_block, cfg, _ = CASES["water+snow, deterministic"]

    def make():  # stirred: particles change corner nodes, so the runs' make-up keeps changing
        parts = make_block()
        parts.v[:] = np.random.default_rng(7).normal(0.0, 0.5, parts.v.shape)
        return parts

    ref, ref_reports, _ = _run("host", mats, make(), cfg, 4)
    out, reports, clock = _run("device", mats, make(), cfg, 4)
    assert [r.substeps for r in reports] == [r.substeps for r in ref_reports]
    np.testing.assert_allclose(out["x"], ref["x"], rtol=0, atol=1e-4)
    np.testing.assert_allclose(out["v"], ref["v"], rtol=0, atol=1e-3)
    again, _, clock2 = _run("device", mats, make(), cfg, 4)
    solver = _solver("device", mats, cfg, "brick")
    state = solver.init_state(make())
    for f in range(2):
        solver.advance(state, f / 24, (f + 1) / 24)
    resumed = _solver("device", mats, cfg, "brick")
    state2, _ = resumed.restore(solver.checkpoint(state, 2 / 24))
    for f in (2, 3):
        resumed.advance(state2, f / 24, (f + 1) / 24)
    for key in ref:
        np.testing.assert_array_equal(again[key], out[key], err_msg=key)
        np.testing.assert_array_equal(resumed.state_to_numpy(state2)[key], out[key], err_msg=key)
    assert clock == clock2


@pytest.mark.parametrize("case", ["rejections", "sand"])
def test_brick_p2g_keeps_the_particles_in_its_order_and_gives_them_back_in_theirs(case):
    """The brick P2G stores the particles in its sort order (a sorting substep's G2P moves them
    and their constants, State.pid); substeps rejected after a sort, checkpoints and host copies
    still see every particle as itself: the host loop's particles, in its order."""
    mats, make, cfg, frames = CASES[case]
    cfg = {**cfg, "deterministic": False}
    ref, ref_reports, _ = _run("host", mats, make(), cfg, frames)
    solver = _solver("device", mats, cfg, "brick")
    state = solver.init_state(make())
    reports = [solver.advance(state, f / 24, (f + 1) / 24) for f in range(frames)]
    assert [r.substeps for r in reports] == [r.substeps for r in ref_reports]
    if case == "rejections":
        assert sum(r.rejected_substeps for r in reports) > 0
    pid = state.pid.numpy()
    assert state.permuted and sorted(pid) == list(range(state.n)) and np.any(pid != np.arange(state.n))
    # the slots are in brick order (a few substeps' travel since the last sort aside)
    g = solver.config.grid_n
    b = np.floor(state.cur.x.numpy() * g - 0.5).astype(int) // 4
    key = (b[:, 0] * 64 + b[:, 1]) * 64 + b[:, 2]
    assert np.mean(np.diff(key) >= 0) > 0.9
    out = solver.state_to_numpy(state)
    for k in ("material", "body", "mass", "volume"):
        np.testing.assert_array_equal(out[k], ref[k], err_msg=k)
    np.testing.assert_allclose(out["x"], ref["x"], rtol=0, atol=1e-4)
    np.testing.assert_allclose(out["v"], ref["v"], rtol=0, atol=1e-3)
    # a checkpoint is in particle order, and restores the slots as they were
    data = solver.checkpoint(state, frames / 24)
    np.testing.assert_array_equal(data["x"], out["x"])
    again, _ = solver.restore(data)
    np.testing.assert_array_equal(again.pid.numpy(), pid)
    np.testing.assert_array_equal(again.cur.x.numpy(), state.cur.x.numpy())
    np.testing.assert_array_equal(again.material.numpy(), state.material.numpy())
