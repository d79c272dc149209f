"""`mpmfx bench surface` measures what shots run with (CPU, small)."""

from pathlib import Path

import numpy as np

from mpmfx.bench.surface_cases import OURS, measure, sample_shape
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING


def test_fine_is_the_surface_stage_setting_at_the_shipped_radius():
    from mpmfx.shotfile import load_shot_config
    from mpmfx.stages.surface import surface_params

    shot = load_shot_config(
        Path(__file__).parents[2] / "pipeline" / "shots" / "snow_smash.toml"
    )  # no [surface] section: the defaults
    h = shot.particle_spacing
    stage = surface_params(shot, shot.surface_groups()[0])
    fine = OURS["fine"]
    assert stage.particle_radius == PARTICLE_RADIUS_PER_SPACING * h
    assert np.isclose(stage.resolved_voxel_size, fine["voxel_h"] * h)
    assert (stage.smooth_iters, stage.min_feature_particles) == (fine["smooth_iters"], fine["min_feature_particles"])
    assert stage.sharp_edges is fine["sharp_edges"] is True
    assert (stage.kernel_radius, stage.radius_scale, stage.dilate) == (3.7, 1.0, 0.0)


def test_a_row_reports_stage_times_and_the_shipped_radius():
    sample = sample_shape("sphere", 2000, "lattice")
    row = measure("sphere", 2000, "lattice", device="cpu", sample=sample, label="fast", **OURS["fast"])
    assert row["method"] == "mpmfx fast" and row["settings"].startswith(f"r {PARTICLE_RADIUS_PER_SPACING:g}h")
    assert {"field", "mesh", "device", "download", "active_blocks"} <= set(row["stages"])
    assert row["components"] == 1 and row["err_mean_h"] < 0.2
    # temporal coherence: the very same particles give the very same mesh, and a body at rest
    # (particles creeping 0.01 h per frame) moves its surface about as little
    assert row["repeat_h"] == 0.0
    assert row["jitter_h"] < 0.03, f"vertex jitter {row['jitter_h']:.4f} h"  # measured ~0.01 h


def test_surface_error_is_the_area_weighted_distance():
    from mpmfx.bench.surface_cases import surface_error

    plane = lambda p: p[:, 2]  # noqa: E731  signed distance to z = 0
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    quads = np.array([[0, 1, 2], [0, 2, 3]])
    assert np.isclose(surface_error(square + [0, 0, 0.3], quads, plane), 0.3)
    # a square rising from z = 0 to z = 1 along x: |z| averages 0.5 over its area
    ramp = square.copy()
    ramp[:, 2] = ramp[:, 0]
    assert np.isclose(surface_error(ramp, quads, plane), 0.5)
    # one big triangle at 0 and one of a hundredth of its area at 1: the mean is by area, not by triangle
    tris = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], float)
    assert np.isclose(surface_error(tris, np.array([[0, 1, 2], [3, 4, 5]]), plane), 1 / 101)


def test_surface_error_does_not_move_with_the_voxel_grid():
    """The same random box surfaced at three sub-voxel offsets: its surface error holds to
    0.002 h (the vertex mean, which samples the surface where marching cubes puts vertices,
    moved 0.130-0.137 h here)."""
    from mpmfx.bench.surface_cases import shape_sdf, surface_error
    from mpmfx.surface import SurfaceParams, surface_particles

    x, h = sample_shape("box", 20_000, "random")
    sdf = shape_sdf("box")[0]
    params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=0.6 * h, smooth_iters=4, dense_output=False)
    errors = []
    for offset in (0.0, 0.25, 0.5):  # voxels
        shift = np.float32(offset * params.voxel_size)
        mesh = surface_particles(x + shift, None, params, device="cpu").mesh
        errors.append(surface_error(mesh.vertices.astype(np.float64) - shift, mesh.faces, sdf) / h)
    assert max(errors) - min(errors) < 0.002, errors  # measured 0.1293-0.1295 h
    assert max(errors) < 0.15, errors
