"""The stage stores leaves; export rebuilds dense grids from them for the VDB writer."""

import numpy as np

from mpmfx.surface import SparseLevelSet


def test_leaves_paste_into_dense_level_set_and_velocity():
    blocks = np.stack([np.full((8, 8, 8), 0.1, np.float32), np.full((8, 8, 8), -0.05, np.float32)])
    vel = np.zeros((2, 8, 8, 8, 3), np.float32)
    vel[1, ..., 1] = 2.0
    s = SparseLevelSet(
        block_ijk=np.array([[0, 0, 0], [8, 0, 0]]),
        values=blocks,
        velocity=vel,
        inside_ijk=np.array([[16, 0, 0]]),
        voxel_size=0.01,
        background=0.3,
    )
    ls = s.to_dense(ijk0=np.array([0, 0, 0]), shape=(24, 8, 16))
    v = s.velocity_dense(ls.ijk0, ls.values.shape)
    assert ls.values[3, 3, 3] == np.float32(0.1) and ls.values[12, 3, 3] == np.float32(-0.05)
    assert ls.values[20, 3, 3] == np.float32(-0.3)  # wholly-inside leaf
    assert ls.values[3, 3, 12] == np.float32(0.3)  # nothing stored: outside
    assert v.shape == (24, 8, 16, 3) and v[12, 3, 3, 1] == 2.0 and v[3, 3, 3, 1] == 0.0


def test_density_leaves_paste_with_inside_leaves_at_one():
    blocks = np.full((1, 8, 8, 8), 0.1, np.float32)
    fog = np.full((1, 8, 8, 8), 0.25, np.float16)  # the stage stores half precision
    s = SparseLevelSet(
        block_ijk=np.array([[0, 0, 0]]),
        values=blocks,
        velocity=None,
        inside_ijk=np.array([[8, 0, 0]]),
        voxel_size=0.01,
        background=0.3,
        density=fog,
    )
    d = s.density_dense(np.array([0, 0, 0]), (24, 8, 8))
    assert d.dtype == np.float32 and d.shape == (24, 8, 8)
    assert d[3, 3, 3] == 0.25 and d[12, 3, 3] == 1.0 and d[20, 3, 3] == 0.0
    assert s.velocity_dense(np.array([0, 0, 0]), (24, 8, 8)) is None
