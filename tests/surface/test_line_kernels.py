"""The CPU variant of each pass (mpmfx.surface.variants.BY_BLOCK: a block per thread, the
topology fills on bit words, launches split across CPU threads) surfaces exactly as the GPU
variant (BY_VOXEL): same mesh, same leaves (compacted as on a GPU: output.leaves_by_voxel)."""

import numpy as np
import pytest

from mpmfx.bench.surface_cases import sample_shape
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles

pytest.importorskip("warp")


def splash(count: int) -> tuple[np.ndarray, float]:
    """A thin random sheet (no INSIDE tile) with 40 drops of 1-12 particles above it, some of
    them under min_feature_particles, and 6 filaments of 12 particles 0.8 h apart: each spans
    blocks that hold too few of its particles to pass as a body, so only labels carried from
    block to block count them whole."""
    x, h = sample_shape("box", count, "random")
    x[:, 1] *= 0.12
    rng = np.random.default_rng(3)
    drops = [
        c + rng.uniform(-0.5 * h, 0.5 * h, size=(n, 3))
        for c, n in zip(rng.uniform([-0.3, 0.1, -0.25], [0.3, 0.7, 0.25], size=(40, 3)), rng.integers(1, 13, size=40))
    ]
    axes = rng.normal(size=(6, 3))
    threads = [
        c + np.outer(0.8 * h * np.arange(12), a / np.linalg.norm(a))
        for c, a in zip(rng.uniform([-0.2, 0.75, -0.2], [0.2, 0.9, 0.2], size=(6, 3)), axes)
    ]
    return np.concatenate([x, *drops, *threads]).astype(np.float32), h


# the box holds INSIDE tiles (the bodies' fill, tile neighbours in every stencil), the torus none;
# close_voids runs one more redistance (close.close_voids); the splash's sheet and drops go
# through the component labels of components.remove_small
@pytest.mark.parametrize(
    "shape, count, voxel_h, iters, close",
    [
        ("torus", 6000, 0.6, 2, 0.0),
        ("torus", 6000, 0.5, 5, 0.0),
        ("box", 8000, 0.5, 5, 0.0),
        ("torus", 6000, 0.6, 2, 1.0),
        ("splash", 6000, 0.5, 5, 0.0),
    ],
)
def test_cpu_line_kernels_and_threads_give_the_voxel_kernels_surface(monkeypatch, shape, count, voxel_h, iters, close):
    from mpmfx.surface import field, variants

    x, h = splash(count) if shape == "splash" else sample_shape(shape, count, "random")
    v = np.random.default_rng(1).normal(size=x.shape).astype(np.float32)
    params = SurfaceParams(
        PARTICLE_RADIUS_PER_SPACING * h,
        voxel_size=voxel_h * h,
        smooth_iters=iters,
        min_feature_particles=8,
        dense_output=False,
        close_voids=close * h,
    )
    monkeypatch.setenv("MPMFX_SURFACE_THREADS", "3")  # more chunks than cores: any split must agree
    monkeypatch.setattr("mpmfx.surface.launch.MIN_SPLIT", 64)
    monkeypatch.setattr("mpmfx.surface.launch.LIGHT_MIN_SPLIT", 8)
    monkeypatch.setattr(field, "BLUR_MIN_SPLIT", 8)  # the weight blur's passes behind a barrier (launch_sequence)
    lines = surface_particles(x, v, params, device="cpu")
    monkeypatch.setattr(variants, "LINE_KERNELS_ON_CPU", False)
    monkeypatch.setenv("MPMFX_SURFACE_THREADS", "1")
    voxels = surface_particles(x, v, params, device="cpu")
    assert len(lines.mesh.faces) > 1000
    for a, b in [
        (lines.mesh.vertices, voxels.mesh.vertices),
        (lines.mesh.faces, voxels.mesh.faces),
        (lines.mesh.velocities, voxels.mesh.velocities),
        (lines.sparse.values, voxels.sparse.values),
        (lines.sparse.block_ijk, voxels.sparse.block_ijk),
        (lines.sparse.velocity, voxels.sparse.velocity),
        (lines.sparse.inside_ijk, voxels.sparse.inside_ijk),
    ]:
        np.testing.assert_array_equal(a, b)


def test_a_bad_thread_count_names_the_variable(monkeypatch):
    from mpmfx.surface.launch import cpu_threads

    monkeypatch.setenv("MPMFX_SURFACE_THREADS", "two")
    with pytest.raises(ValueError, match="MPMFX_SURFACE_THREADS='two'"):
        cpu_threads()
    monkeypatch.setenv("MPMFX_SURFACE_THREADS", "2")
    assert cpu_threads() == 2


@pytest.mark.parametrize("sampling", ["lattice", "random"])
@pytest.mark.parametrize("voxel_h, iters", [(0.6, 2), (0.5, 5)])
def test_cpu_near_blocks_are_mark_near_blocks(monkeypatch, sampling, voxel_h, iters):
    """classify.near_blocks_by_block (a block of particles per thread, most blocks decided from
    the block's span) marks exactly the blocks near_blocks_by_voxel (mark_near_blocks) marks,
    lattice planes on block faces included."""
    import warp as wp

    from mpmfx.surface import binning, classify
    from mpmfx.surface.grid import SparseGrid

    monkeypatch.setenv("MPMFX_SURFACE_THREADS", "3")
    monkeypatch.setattr("mpmfx.surface.launch.MIN_SPLIT", 64)
    x, h = sample_shape("torus", 6000, sampling)
    params = SurfaceParams(
        PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel_h * h, smooth_iters=iters, dense_output=False
    )
    xd = wp.array(x, dtype=wp.vec3, device="cpu")
    with wp.ScopedDevice("cpu"):
        grid = SparseGrid(*binning.particle_bounds(xd), params)
        g = binning.grid_positions(xd, grid)
        _, cells, starts, order = binning.bin_particles_by_block(g, grid)
        gs = binning.sorted_positions(g, order)
        want = wp.zeros(grid.nblocks, dtype=wp.int32)
        wp.launch(classify.mark_near_blocks, g.shape[0], inputs=[g, grid.reach_vox, want, 0])
        got = wp.zeros(grid.nblocks, dtype=wp.int32)
        classify.near_blocks_by_block(gs, cells, starts, grid, got)
    nb = int(np.prod(grid.nblocks))
    assert 0 < want.numpy().sum() < nb
    np.testing.assert_array_equal(got.numpy(), want.numpy())


def test_keeping_freed_memory_respects_the_users_malloc_settings(monkeypatch):
    """cpu_memory leaves glibc alone where the user opted out or tuned malloc themselves."""
    from mpmfx.surface import cpu_memory

    for name, value in [
        ("MPMFX_SURFACE_KEEP_MEMORY", "0"),
        ("GLIBC_TUNABLES", "glibc.malloc.trim_threshold=1"),
        ("MALLOC_ARENA_MAX", "2"),
    ]:
        monkeypatch.setattr(cpu_memory, "_done", False)
        monkeypatch.setenv(name, value)
        assert cpu_memory.keep_freed_memory() is False
        monkeypatch.delenv(name)
    assert cpu_memory.keep_freed_memory() is False  # once a process
