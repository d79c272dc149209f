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


@pytest.mark.parametrize("with_v", [True, False])
def test_half_attributes_are_numpys_rounding_from_the_device_kernel_and_the_host(with_v):
    """SurfaceParams.half_attributes: normals and velocities come back as float16, rounded as
    numpy rounds them (what a frame file stored before), whether the device converts them (the
    GPU's download, run here on CPU arrays) or the host does (the CPU's)."""
    import warp as wp

    from mpmfx.surface.output import mesh_by_block, mesh_by_voxel

    rng = np.random.default_rng(5)
    n = 5000
    normals = rng.normal(size=(n, 3)).astype(np.float32)
    vel = (rng.normal(size=(n, 3)) * 30).astype(np.float32)

    def device_mesh():
        as_vec = lambda a: wp.array(a, dtype=wp.vec3, device="cpu")  # noqa: E731
        faces = wp.array(rng.integers(0, n, 3 * 2 * n).astype(np.int32), device="cpu")
        return (as_vec(normals * 0), as_vec(normals), as_vec(vel), faces)

    for download in (mesh_by_voxel, mesh_by_block):
        m = download(device_mesh(), with_v=with_v, pinned=False, half=True)
        assert m.normals.dtype == m.velocities.dtype == np.float16
        np.testing.assert_array_equal(m.normals, normals.astype(np.float16))
        np.testing.assert_array_equal(m.velocities, vel.astype(np.float16) if with_v else 0)
