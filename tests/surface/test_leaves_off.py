"""SurfaceParams.leaves off: the same mesh, no leaves copied back (what a shot without VDB asks)."""

import numpy as np
import pytest

from mpmfx.surface import SurfaceParams, surface_particles

pytest.importorskip("warp")


def test_without_leaves_the_mesh_is_the_same_and_no_block_comes_back():
    rng = np.random.default_rng(3)
    x = (rng.random((4000, 3)) * 0.3).astype(np.float32)
    v = np.tile(np.float32([0.0, -1.0, 0.5]), (len(x), 1))
    runs = {}
    for leaves in (True, False):
        p = SurfaceParams(0.012, voxel_size=0.01, smooth_iters=2, dense_output=False, leaves=leaves)
        runs[leaves] = surface_particles(x, v, p, device="cpu")
    on, off = runs[True], runs[False]
    np.testing.assert_array_equal(on.mesh.vertices, off.mesh.vertices)
    np.testing.assert_array_equal(on.mesh.faces, off.mesh.faces)
    np.testing.assert_array_equal(on.mesh.velocities, off.mesh.velocities)
    assert len(on.sparse.block_ijk) > 0 and len(off.sparse.block_ijk) == 0 and len(off.sparse.inside_ijk) == 0
    assert off.sparse.values.shape == (0, 8, 8, 8) and off.sparse.velocity.shape == (0, 8, 8, 8, 3)
    assert (off.sparse.voxel_size, off.sparse.background) == (on.sparse.voxel_size, on.sparse.background)
    with pytest.raises(ValueError, match="SurfaceParams.leaves"):
        SurfaceParams(0.01, leaves="no")
