"""The fog density on the sparse leaves (SurfaceParams.density): 1 in the bulk of a body, about
one half on its surface, 0 outside; off by default, and it leaves the level set alone (CPU)."""

import numpy as np
import pytest

from mpmfx.surface import SurfaceParams, surface_particles
from tests.surface.dense_reference import surface_dense

pytest.importorskip("warp")

H = 0.02  # particle spacing (m)


def lattice_cube(n: int) -> np.ndarray:
    """(n^3, 3) float32 particles on a cubic lattice of spacing H, centred on the origin."""
    g = (np.arange(n) - (n - 1) / 2) * H
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)


@pytest.fixture(scope="module")
def blob():
    """The pipeline's settings (radius 0.6 spacing, voxel half a spacing) with and without density."""
    x = lattice_cube(14)
    runs = {}
    for density in (False, True):
        p = SurfaceParams(0.6 * H, voxel_size=0.5 * H, smooth_iters=1, dense_output=False, density=density)
        runs[density] = surface_particles(x, None, p, device="cpu").sparse
    return runs


def test_density_is_one_deep_inside_and_falls_to_zero_across_the_surface(blob):
    sp = blob[True]
    assert sp.density.shape == sp.values.shape and sp.density.dtype == np.float32
    assert sp.density.min() >= 0.0 and sp.density.max() <= 1.0
    d, phi, band = sp.density, sp.values, sp.background
    deep, surface, out = phi <= -band, np.abs(phi) < 0.25 * sp.voxel_size, phi >= band
    assert deep.any() and surface.any() and out.any()
    assert d[deep].min() > 0.9, "the bulk of the body is not dense"
    assert 0.35 < d[surface].mean() < 0.65, f"density on the zero level {d[surface].mean():.2f}, not ~0.5"
    assert d[out].mean() < 0.03 and d[out].max() < 0.2, "fog reaches far outside the surface"
    # the wholly-inside leaves are 1 and nothing beyond the leaves is stored
    ls = sp.to_dense()
    dense = sp.density_dense(ls.ijk0, ls.values.shape)
    assert np.all(dense[ls.values <= -band] > 0.9) and np.all(dense[ls.values >= band] < 0.2)


def test_density_is_off_by_default_and_changes_nothing_else(blob):
    assert SurfaceParams(0.01).density is False
    off, on = blob[False], blob[True]
    assert off.density is None and off.density_dense(np.zeros(3, np.int64), (8, 8, 8)) is None
    assert np.array_equal(off.block_ijk, on.block_ijk) and np.array_equal(off.values, on.values)


def test_density_needs_the_sparse_zhu_bridson_surfacer():
    with pytest.raises(ValueError, match="SurfaceParams.density"):
        surface_dense(lattice_cube(4), None, SurfaceParams(0.01, density=True), device="cpu")
