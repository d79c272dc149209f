import numpy as np
import pytest
import trimesh

from mpmfx.geometry.mesh import transform_mesh
from mpmfx.geometry.voxelise import voxelise


@pytest.mark.parametrize(
    "mesh",
    [
        trimesh.creation.icosphere(subdivisions=4, radius=0.3),
        # turned, so faces do not line up with the particle lattice
        transform_mesh(trimesh.creation.box(extents=(0.5, 0.3, 0.4)), rotate_deg=(20, 0, 30)),
    ],
    ids=["sphere", "turned-box"],
)
@pytest.mark.parametrize("grid_n, ppc", [(32, 8), (24, 27)])
def test_particle_count_matches_volume(domain, mesh, grid_n, ppc):
    vox = voxelise(mesh, grid_n=grid_n, ppc=ppc, **domain)
    dx = domain["size"] / grid_n
    expected = mesh.volume / dx**3 * ppc
    assert len(vox.points) == pytest.approx(expected, rel=0.03)
    assert vox.volume.sum() == pytest.approx(mesh.volume, rel=0.03)
    # Jitter may carry a particle at most a quarter sub-cell past the surface.
    depth = trimesh.proximity.signed_distance(mesh, vox.points[::50])  # > 0 inside
    assert depth.min() > -0.25 * dx / round(ppc ** (1 / 3)) - 1e-9


def test_same_seed_same_particles_other_seed_differs(domain):
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.25)
    a = voxelise(mesh, grid_n=16, seed=3, **domain)
    b = voxelise(mesh, grid_n=16, seed=3, **domain)
    c = voxelise(mesh, grid_n=16, seed=4, **domain)
    np.testing.assert_array_equal(a.points, b.points)
    assert a.points.shape == c.points.shape and not np.array_equal(a.points, c.points)


def test_sdf_is_signed_distance_on_domain_nodes(domain):
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.3)
    vox = voxelise(mesh, grid_n=32, **domain)
    dx = domain["size"] / 32
    # Domain aligned: sdf_origin is a grid node.
    off = (vox.sdf_origin - np.asarray(domain["origin"])) / dx
    np.testing.assert_allclose(off, np.round(off), atol=1e-9)
    idx = np.argwhere(np.ones(vox.sdf.shape, bool))
    truth = np.linalg.norm(vox.sdf_origin + idx * vox.sdf_voxel, axis=1) - 0.3
    err = np.abs(vox.sdf.ravel() - truth)
    near = np.abs(truth) < dx
    assert err[near].max() < 0.05 * dx  # exact up to the facetting of the sphere
    assert err.max() < 1.0 * dx
    assert vox.sdf.min() < -0.25  # covers the interior, negative inside
    assert np.all(vox.sdf.shape >= np.ceil(0.6 / dx) + 4)


def test_open_mesh_warns_and_still_fills(domain):
    closed = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    mesh = closed.copy()
    mesh.update_faces(np.arange(len(mesh.faces)) >= 8)  # punch a hole
    with pytest.warns(UserWarning, match=r"not watertight \(\d+\.\d% of edges open\)"):
        vox = voxelise(mesh, grid_n=16, **domain)
    assert not vox.watertight and 0 < vox.open_fraction < 0.05
    ref = voxelise(closed, grid_n=16, **domain)
    assert len(vox.points) == pytest.approx(len(ref.points), rel=0.02)


def test_overlapping_parts_count_once(domain):
    a = trimesh.creation.box(extents=(0.4, 0.3, 0.2))
    b = trimesh.creation.box(extents=(0.2, 0.2, 0.4))
    both = trimesh.util.concatenate([a, b])  # self-intersecting, not a union
    union_volume = 0.4 * 0.3 * 0.2 + 0.2 * 0.2 * 0.4 - 0.2 * 0.2 * 0.2
    vox = voxelise(both, grid_n=32, **domain)
    assert vox.volume.sum() == pytest.approx(union_volume, rel=0.05)


def test_ppc_must_be_a_cube(domain):
    with pytest.raises(ValueError, match="perfect cube"):
        voxelise(trimesh.creation.box(), grid_n=8, ppc=10, **domain)
