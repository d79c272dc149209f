"""Animated mesh colliders (mpmfx.mpm.animated): a deforming mesh pushes material with its own
surface velocity, from vertex motion, not a rigid pose."""

import numpy as np
import pytest

from mpmfx.geometry.animated import load_animation
from mpmfx.mpm import AnimatedMesh, Solver, SolverConfig, preset
from tests.anim_assets import growing_cube_usd
from tests.mpm.mpm_helpers import block, concat

G, S, H0, C = 32, 0.2, 0.1, (0.5, 0.5, 0.5)  # grid; face speed (domain/s); half size; centre
FPS = 24.0


def _growing_cube(tmp_path) -> AnimatedMesh:
    """The cube of tests/anim_assets.py as a time-sampled USD (frames 1..9) read back by the
    collider loader; the domain is 1 m, so metres are domain units."""
    frames = list(range(1, 10))
    path = growing_cube_usd(tmp_path / "grow.usda", centre=C, half0=H0, speed=S, frames=frames, fps=FPS)
    anim = load_animation(path, frames, FPS)
    times = (np.array(frames) - 1) / FPS
    return AnimatedMesh(times, anim.points.astype(np.float32), anim.faces, friction=0.0)


def _run(mesh, stepper="device", frames=7):
    # water on both sides of the cube along x: a rigid pose cannot push both outward
    right = block((C[0] + H0, 0.4, 0.4), (C[0] + H0 + 0.15, 0.6, 0.6), grid_n=G)
    left = block((C[0] - H0 - 0.15, 0.4, 0.4), (C[0] - H0, 0.6, 0.6), grid_n=G)
    solver = Solver(
        [preset("Water")],
        SolverConfig(grid_n=G, gravity=(0.0, 0.0, 0.0)),
        animated=[mesh],
        device="cpu",
        stepper=stepper,
    )
    state = solver.init_state(concat(right, left))
    out = []
    for f in range(frames):
        solver.advance(state, f / FPS, (f + 1) / FPS)
        out.append({k: np.array(v) for k, v in solver.state_to_numpy(state).items()})
    return out


def test_a_growing_cube_pushes_material_out_at_its_face_speed(tmp_path):
    """Material against the +x and -x faces of a cube growing at S domain/s a face moves out
    at S: the mean x-velocity of the particles within 3/4 cell of each face, over frames 3..7,
    is within 25 % of +S and -S (water: it flows aside as well, so the layer at the face lags
    the face a little; a rigid box collider translated at S gives the same ~0.8 S), and no
    particle is more than a cell inside the cube."""
    mesh = _growing_cube(tmp_path)
    got = {+1: [], -1: []}
    for f, st in enumerate(_run(mesh)):
        x, v = st["x"], st["v"]
        half = H0 + S * (f + 1) / FPS
        mid = (np.abs(x[:, 1] - C[1]) < 0.06) & (np.abs(x[:, 2] - C[2]) < 0.06)
        for side in (+1, -1):
            mine = mid & (side * (x[:, 0] - C[0]) > 0)
            depth = side * (x[:, 0] - C[0]) - half  # > 0 outside the face
            assert depth[mine].min() > -1.0 / G
            near = mine & (depth < 0.75 / G)
            if f >= 2:
                got[side].append(v[near, 0].mean())
    assert np.mean(got[+1]) == pytest.approx(S, rel=0.25)
    assert np.mean(got[-1]) == pytest.approx(-S, rel=0.25)


def test_the_device_stepper_and_the_host_loop_agree_bit_for_bit(tmp_path):
    mesh = _growing_cube(tmp_path)
    a = _run(mesh, "device", frames=2)[-1]
    b = _run(mesh, "host", frames=2)[-1]
    assert np.array_equal(a["x"], b["x"]) and np.array_equal(a["v"], b["v"])


def test_a_resume_from_a_checkpoint_is_bit_identical(tmp_path):
    """The collider's pose is a function of the shot time alone, so a resumed run (a new solver
    from a checkpoint) continues exactly as the uninterrupted one."""
    mesh = _growing_cube(tmp_path)
    whole = _run(mesh, frames=3)[-1]

    def solver():
        return Solver([preset("Water")], SolverConfig(grid_n=G, gravity=(0.0, 0.0, 0.0)), animated=[mesh], device="cpu")

    right = block((C[0] + H0, 0.4, 0.4), (C[0] + H0 + 0.15, 0.6, 0.6), grid_n=G)
    left = block((C[0] - H0 - 0.15, 0.4, 0.4), (C[0] - H0, 0.6, 0.6), grid_n=G)
    s = solver()
    st = s.init_state(concat(right, left))
    s.advance(st, 0.0, 1 / FPS)
    ckpt = s.checkpoint(st, 1 / FPS)
    s2 = solver()
    st2, t = s2.restore(ckpt)
    for f in (1, 2):
        s2.advance(st2, f / FPS, (f + 1) / FPS)
    got = s2.state_to_numpy(st2)
    assert np.array_equal(got["x"], whole["x"]) and np.array_equal(got["v"], whole["v"])
