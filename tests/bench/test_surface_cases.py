"""`mpmfx bench surface` measures what shots run with (CPU, small)."""

from pathlib import Path

import numpy as np

from mpmfx.bench.surface_cases import OURS, measure, sample_shape
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING


def test_fine_is_the_surface_stage_setting_at_the_shipped_radius():
    from mpmfx.config import load_shot_config
    from mpmfx.stages.surface import surface_params

    shot = load_shot_config(Path(__file__).parents[2] / "pipeline" / "shots" / "jelly_splash.toml")
    h = shot.particle_spacing
    stage = surface_params(shot)
    fine = OURS["fine"]
    assert stage.particle_radius == PARTICLE_RADIUS_PER_SPACING * h
    assert np.isclose(stage.resolved_voxel_size, fine["voxel_h"] * h)
    assert (stage.smooth_iters, stage.min_feature_particles) == (fine["smooth_iters"], fine["min_feature_particles"])
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
