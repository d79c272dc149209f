"""The tyre_mud shot's tyre (assets/tyre.usda, a time-sampled translate and rotateZ made by
assets/make_tyre.py) loads as an animated collider that rolls without slip: the surface
velocity the grid update meets is ~0 at the contact patch and ~2v on top."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import trimesh

from mpmfx.mpm.animated import AnimatedMeshes
from mpmfx.shotfile import load_shot_config
from mpmfx.stages import simulate

ROOT = Path(__file__).resolve().parents[2]


def _make_tyre():
    spec = importlib.util.spec_from_file_location("make_tyre", ROOT / "assets" / "make_tyre.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _surface_velocity(mesh: trimesh.Trimesh, vel: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, float]:
    """(velocity (m/s) of the surface point closest to `at`, barycentric in the vertex
    velocities as wp.mesh_eval_velocity takes it; its distance from `at` (m))."""
    cp, dist, tri = trimesh.proximity.closest_point(mesh, at[None])
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[tri], cp)[0]
    return bary @ vel[mesh.faces[tri[0]]], float(dist[0])


def test_the_tyre_rolls_without_slip_as_the_grid_sees_it():
    tyre = _make_tyre()
    shot = load_shot_config(ROOT / "pipeline" / "shots" / "tyre_mud.toml")
    (anim,) = simulate.animated_meshes(shot)
    origin, size = np.asarray(shot.domain.origin), shot.domain.size
    meshes = AnimatedMeshes([anim], "cpu", dx=1.0 / shot.domain.grid_n)
    # Mid-frame 16..17 (the middle of a frame interval: the vertices' chord velocity is then
    # the rolling's own), a tread bar under the axle (a bar is centred there at 0.628 s).
    t = 15.5 / shot.shot.fps
    meshes.pose_host(t, t + 1e-3, 1e-3)
    pts = meshes.wp_meshes[0].points.numpy() * size + origin
    vel = meshes.wp_meshes[0].velocities.numpy() * size
    mesh = trimesh.Trimesh(pts, anim.triangles, process=False)
    axle = pts.mean(axis=0)  # the tyre is symmetric about its axle
    down = np.array([0.0, tyre.RADIUS, 0.0])
    v = tyre.SPEED
    np.testing.assert_allclose(axle[1], tyre.BED_TOP - tyre.SINK + tyre.RADIUS, atol=1e-3)

    v_bottom, gap = _surface_velocity(mesh, vel, axle - down)
    assert gap < 2e-3  # the contact point is on a bar's face
    assert np.linalg.norm(v_bottom) < 0.02 * v, v_bottom  # stands still on the ground
    v_top, gap = _surface_velocity(mesh, vel, axle + down)
    assert gap < 2e-3
    np.testing.assert_allclose(v_top, [2 * v, 0.0, 0.0], atol=0.02 * v)
    # The axle moves at v, every vertex as the rigid roll about the contact point says.
    omega = -v / tyre.RADIUS  # rad/s about +z
    rel = pts - (axle - down)
    rigid = np.stack([-omega * rel[:, 1], omega * rel[:, 0], np.zeros(len(rel))], axis=1)
    assert np.abs(vel - rigid).max() < 0.03 * v
