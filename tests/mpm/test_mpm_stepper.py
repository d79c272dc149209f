"""The device stepper (chunks of substeps decided on the device, stepper.py / chunked.py, with
the brick P2G of p2g_brick.py) against the reference host loop and reference P2G, over a
few hundred substeps on the CPU: deterministic mode bit for bit (the same substeps,
rejections and particles; on CUDA the brick P2G differs in the last bits, see its module); fast mode sums each node's float contributions in another order, so there the
same substeps and positions within 1e-4 domain units (1/600 of a cell), velocities within
1e-3 domain/s."""

import numpy as np
import pytest

from tests.mpm.mpm_helpers import block, concat
from mpmfx.mpm import SimulationError, Solver, SolverConfig, preset

CASES = {
    # name: (materials, particles, config overrides, frames)
    "water+snow, deterministic": (["Water", "Mushy"], lambda: concat(
        block((0.2, 0.15, 0.2), (0.45, 0.4, 0.8), grid_n=16),
        block((0.55, 0.15, 0.2), (0.8, 0.4, 0.8), grid_n=16, material=1)), {}, 6),
    "sand": (["Granular"], lambda: block((0.3, 0.2, 0.3), (0.7, 0.5, 0.7), grid_n=16), {}, 6),
    "water+snow, fast mode": (["Water", "Mushy"], lambda: concat(
        block((0.2, 0.15, 0.2), (0.45, 0.4, 0.8), grid_n=16),
        block((0.55, 0.15, 0.2), (0.8, 0.4, 0.8), grid_n=16, material=1)), {"deterministic": False}, 6),
    "rejections": (["Elastic"], lambda: block((0.3, 0.2, 0.3), (0.6, 0.45, 0.6), grid_n=16),
                   {"cfl": 1.0, "damping": 1.0, "gravity": (0, -4e4, 0)}, 2),
    # keyframed colliders (posed on the device by the device stepper): a box sweeping and
    # turning through snow, a sphere that stays, time_scale != 1
    "colliders": (["Mushy"], lambda: block((0.25, 0.15, 0.25), (0.75, 0.4, 0.75), grid_n=16),
                  {"time_scale": 0.8}, 5),
}


def _colliders():
    from scipy.spatial.transform import Rotation
    from mpmfx.mpm import Collider, ColliderKind
    quats = Rotation.from_euler("y", [[0], [50], [140]], degrees=True).as_quat().astype(np.float32)
    box = Collider(ColliderKind.BOX, half_extents=(0.04, 0.12, 0.2), friction=0.3, times=[0.0, 0.09, 0.2],
                   translations=[(0.15, 0.3, 0.5), (0.45, 0.27, 0.5), (0.7, 0.3, 0.45)], rotations=quats)
    sphere = Collider(ColliderKind.SPHERE, radius=0.08, translations=[(0.5, 0.2, 0.25)])
    return [box, sphere]


def _run(stepper, mats, parts, cfg, frames):
    colliders = _colliders() if "time_scale" in cfg else ()
    solver = Solver([preset(m) for m in mats], SolverConfig(grid_n=16, **cfg), colliders=colliders, device="cpu",
                    stepper=stepper)
    if not solver.flags.multi_field:  # the GPU's default P2G (the brick one), in fast mode too
        solver._device_advance.p2g = "brick"
    state = solver.init_state(parts)
    reports = [solver.advance(state, f / 24, (f + 1) / 24) for f in range(frames)]
    return solver.state_to_numpy(state), reports, state.clock


@pytest.mark.parametrize("case", CASES)
def test_device_stepper_matches_the_host_loop_bit_for_bit(case):
    mats, make, cfg, frames = CASES[case]
    ref, ref_reports, ref_clock = _run("host", mats, make(), cfg, frames)
    out, reports, clock = _run("device", mats, make(), cfg, frames)
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
        for f in ("substeps", "rejected_substeps", "dt_min", "dt_max", "max_speed", "cfl_used", "j_min", "j_max",
                  "particles_lost", "inverted", "mass", "kinetic_energy"):
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
