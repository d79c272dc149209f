"""Frame files: what a stage writes is what the next one reads, in fewer bytes where it can."""

import numpy as np

from mpmfx.io.frames import GroupSurface, ParticleFrame, SurfaceFrame, write_arrays


def _particles(ids):
    n = len(ids)
    rng = np.random.default_rng(0)
    return ParticleFrame(
        x=rng.random((n, 3), np.float32),
        v=rng.random((n, 3), np.float32),
        id=np.asarray(ids, np.int32),
        material=np.zeros(n, np.int32),
        body=np.zeros(n, np.int32),
        J=np.ones(n, np.float32),
    )


def test_particle_ids_that_count_up_are_rebuilt_not_stored(tmp_path):
    whole = _particles(np.arange(1000))
    whole.write(tmp_path / "a.npz")
    back = ParticleFrame.read(tmp_path / "a.npz")
    np.testing.assert_array_equal(back.id, whole.id)
    assert back.id.dtype == np.int32
    np.testing.assert_array_equal(back.x, whole.x)

    gaps = _particles(np.r_[0:400, 500:1100])  # removed particles: the ids are the record
    gaps.write(tmp_path / "b.npz")
    np.testing.assert_array_equal(ParticleFrame.read(tmp_path / "b.npz").id, gaps.id)
    assert (tmp_path / "b.npz").stat().st_size > (tmp_path / "a.npz").stat().st_size + 3000


def test_surface_normals_and_velocities_are_stored_in_half_precision(tmp_path):
    rng = np.random.default_rng(1)
    n = rng.normal(size=(500, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    vel = rng.normal(scale=4.0, size=(500, 3)).astype(np.float32)
    group = GroupSurface(
        vertices=rng.random((500, 3), np.float32),
        faces=rng.integers(0, 500, (900, 3)).astype(np.int32),
        normals=n,
        velocities=vel,
        block_ijk=np.zeros((1, 3), np.int64),
        blocks=np.ones((1, 8, 8, 8), np.float32),
        inside_ijk=np.zeros((0, 3), np.int64),
        voxel_size=0.01,
        background=0.03,
    )
    SurfaceFrame({"snow": group}).write(tmp_path / "s.npz")
    back = SurfaceFrame.read(tmp_path / "s.npz").groups["snow"]
    np.testing.assert_array_equal(back.vertices, group.vertices)  # positions stay exact
    got = back.normals.astype(np.float32)
    angle = np.degrees(np.arctan2(np.linalg.norm(np.cross(got, n), axis=1), np.sum(got * n, axis=1)))
    assert angle.max() < 0.1  # degrees: far below what shading shows
    np.testing.assert_allclose(back.velocities, vel, rtol=1e-3, atol=1e-3)


def test_frames_of_the_previous_format_still_read(tmp_path):
    old = _particles(np.arange(10))
    arrays = old.arrays()
    path = write_arrays(tmp_path / "old.npz", arrays)
    with np.load(path) as d:  # rewrite the format tag as the previous version wrote it
        data = {k: d[k] for k in d.files}
    data["_format"] = np.int32(1)
    np.savez(path, **data)
    np.testing.assert_array_equal(ParticleFrame.read(path).id, old.id)


def test_a_reader_takes_only_the_arrays_it_names(tmp_path):
    whole = _particles(np.arange(500))
    whole.write(tmp_path / "a.npz")
    part = ParticleFrame.read(tmp_path / "a.npz", fields=("x", "v", "body"))
    np.testing.assert_array_equal(part.x, whole.x)
    np.testing.assert_array_equal(part.body, whole.body)
    assert part.J is None and part.material is None and part.id is None
