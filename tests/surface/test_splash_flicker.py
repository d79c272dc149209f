"""Sheets, splashes and flicker as a user sees them (CPU, small): our anisotropic sheet against a
peer's on the same particles, the water_dam splash frame the bench ships, and a slowly moving
block that must not flicker from frame to frame."""

import numpy as np

from mpmfx.bench import surface_flicker as flicker
from mpmfx.bench import surface_splash as splash
from mpmfx.bench.surface_cases import measure_sheet, measure_sheet_peer
from mpmfx.surface import SurfaceParams, surface_particles


def test_a_peer_sees_the_same_sheet_and_keeps_more_holes_than_our_anisotropic_kernels():
    # 3000 random particles in a disc one spacing thick; measured: splashsurf (no anisotropic
    # mode) 47 holes, ours "fast" anisotropic 1
    ours = measure_sheet(3000, "random", label="fast", device="cpu", anisotropic=True)
    peer = measure_sheet_peer("splashsurf", 3000, "random")
    assert (peer["particles"], peer["h"]) == (ours["particles"], ours["h"])
    assert peer["open_edges"] == 0 and peer["device"].startswith("cpu")
    assert peer["holes"] > 5 * max(ours["holes"], 1), (peer["holes"], ours["holes"])


def test_splash_asset_round_trips_within_a_thousandth_of_the_spacing(tmp_path):
    x = np.random.default_rng(0).uniform([-0.45, 0.0, -0.45], [0.45, 0.4, 0.45], size=(500, 3)).astype(np.float32)
    np.savez(tmp_path / "0003.npz", x=x)
    path = splash.write_splash_asset(tmp_path / "0003.npz", tmp_path / "asset.npz", frame=3)
    y, h = splash.load_splash(path)
    assert np.isclose(h, 1 / 96)  # water_dam: 1 m / 48 cells / 8 particles per cell ^ (1/3)
    assert np.abs(y - x).max() < 1e-3 * h


def test_the_splash_frame_climbs_the_far_wall_and_surfaces_as_one_closed_piece():
    x, h = splash.load_splash()
    assert len(x) == splash.SPLASH_PARTICLES == 52_896
    assert ((x[:, 0] > 0.4) & (x[:, 1] > 0.15)).sum() > 100  # the surge running up the far wall
    wall = x[x[:, 0] > 0.3]  # the run-up and the water under it, ~7k particles
    mesh = surface_particles(wall, None, splash.splash_params(h, anisotropic=False), device="cpu").mesh
    row = splash._row("mpmfx fine", wall, h, 0.0, mesh.vertices, mesh.faces, "cpu", "")
    assert row["components"] == 1 and row["open_edges"] == 0
    assert row["holes"] <= 3, f"{row['holes']} holes through the run-up"


def test_the_flicker_measure_reads_zero_for_a_surface_that_follows_the_body():
    xs, h, step = flicker.moving_frames(2000, frames=3)
    first = surface_particles(xs[0], None, SurfaceParams(0.6 * h, voxel_size=0.6 * h), device="cpu").mesh

    def follows(x):  # the first mesh carried along with the particles' mean
        return first.vertices + (x.mean(axis=0) - xs[0].mean(axis=0)), first.faces

    rows, meshes = flicker.flicker_run(follows, xs, h, step)
    for r in rows[1:]:
        assert r["normal_jitter_h"] < 1e-3 and r["normal_turn_deg"] < 0.1, r
        assert abs(r["area_change"]) < 1e-6 and abs(r["volume_change"]) < 1e-6
    # and in the picture (the camera moves with the body): the follower moves with the particles'
    # mean, a ten-thousandth of h off the body's step, so a few silhouette pixels change (measured
    # 0.02 levels, 0.03 % of the pixels; the surfacers 0.8-1.6 levels, 2.4-5.8 %)
    pictures = flicker.picture_change(meshes)
    assert pictures["pixel_change"] < 0.05 and pictures["pixels_changed"] < 1e-3, pictures


def test_the_picture_measure_sees_a_surface_that_flickers():
    # the same mesh, every other frame 0.1 h bigger: a breathing body (measured 3.6 levels, 8 %
    # of the pixels; a spacing's tenth is the bench's step a frame)
    x, h = flicker.sample_shape("box", 2000, "random")
    mesh = surface_particles(x, None, SurfaceParams(0.6 * h, voxel_size=0.6 * h), device="cpu").mesh
    normals = flicker.vertex_normals(mesh.vertices, mesh.faces)
    frames = [(mesh.vertices + (k % 2) * 0.1 * h * normals, mesh.faces) for k in range(3)]
    pictures = flicker.picture_change(frames)
    assert pictures["pixel_change"] > 1.0 and pictures["pixels_changed"] > 0.03, pictures


def test_a_slowly_moving_block_does_not_flicker():
    # 3000 random particles gliding 0.1 h a frame, creeping 0.01 h; four frames at "fast".
    # Measured: vertices 0.011 h off the previous surface (the creep itself), shading normals
    # turn 1.2 deg on the faces, area and volume change 0.07 % / 0.04 % a frame
    xs, h, step = flicker.moving_frames(3000, frames=4)
    rows, _ = flicker.flicker_run(flicker.ours("fast", h, "cpu"), xs, h, step)
    s = flicker.summarise("mpmfx fast", rows, len(xs[0]), h)
    assert s["normal_jitter_h"] < 0.03, s
    assert s["normal_turn_deg"] < 2.5, s
    assert s["area_change_max"] < 0.005 and s["volume_change_max"] < 0.005, s
    assert s["components_max"] <= 2


def test_a_slowly_moving_block_does_not_flicker_at_the_shot_setting_with_round_edges():
    # as above at "round" (the surface stage's setting with surface.sharp_edges = false; the
    # setting itself: tests/surface/test_sharp_edges.py). The voxels next to the zero crossing
    # start the redistancing at their distance to the plane through the crossings, with the
    # other axes' zero levels extrapolated so that the start does not jump when a crossing
    # appears on another axis between frames. p99 of the vertices' distance to the previous
    # surface: 0.077 h without the plane start, 0.052 h with it ("fast" 0.074 / 0.049).
    # Smoothing more turns the moving box's rounded edges more between frames: p99 normal turn
    # 4.3 / 5.4 degrees at 5 / 8 steps of the curvature flow (the stage's 8), 4.7 / 7.2 with 5 /
    # 8 passes of the blur it replaced; p99 distance 0.049 / 0.055 h
    xs, h, step = flicker.moving_frames(3000, frames=4)
    rows, _ = flicker.flicker_run(flicker.ours("round", h, "cpu"), xs, h, step)
    s = flicker.summarise("mpmfx round", rows, len(xs[0]), h)
    assert s["normal_jitter_h"] < 0.01, s
    assert s["normal_jitter_p99_h"] < 0.062, s
    assert s["normal_turn_p99_deg"] < 5.8, s
