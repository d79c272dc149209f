"""Inside tests of open and badly wound meshes: the capped winding number against the sum over
every triangle (the definition), on the kinds of damage real assets carry."""

import numpy as np
import pytest
import trimesh

from mpmfx.geometry.inside import _RAY_SHIFT, Lattice, boundary_caps, inside_mask, open_winding_number, winding_number


def _holey_sphere(rng, holes: int = 40) -> trimesh.Trimesh:
    ico = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    keep = np.ones(len(ico.faces), bool)
    keep[rng.choice(len(keep), holes, replace=False)] = False
    return trimesh.Trimesh(ico.vertices, ico.faces[keep], process=False)


def _damaged_meshes():
    rng = np.random.default_rng(1)
    holey = _holey_sphere(rng)
    flipped = holey.faces.copy()
    turn = rng.random(len(flipped)) < 0.05
    flipped[turn] = flipped[turn][:, ::-1]
    box = trimesh.creation.box(extents=(0.3, 0.3, 0.3))
    box.apply_translation((0.2, 0.0, 0.0))
    # a lone sheet lying in a lattice plane (z = 0), glued into a closed box
    sheet = trimesh.Trimesh([[0, 0, 0], [0.4, 0, 0], [0.4, 0.3, 0], [0, 0.3, 0]], [[0, 1, 2], [0, 2, 3]])
    return {
        "holes": holey,
        "holes and flipped faces": trimesh.Trimesh(holey.vertices, flipped, process=False),
        "holes overlapping a box": trimesh.util.concatenate([holey, box]),
        "a sheet in a lattice plane": trimesh.util.concatenate([trimesh.creation.box(extents=(0.2,) * 3), sheet]),
    }


@pytest.mark.parametrize("name", list(_damaged_meshes()))
def test_capped_winding_number_is_the_sum_over_every_triangle(name):
    mesh = _damaged_meshes()[name]
    caps = boundary_caps(mesh)
    assert 0 < len(caps) < len(mesh.faces)  # a hole's rim, not the whole mesh
    lat = Lattice(origin=np.array([-0.4, -0.4, -0.4]), h=0.0125, shape=(64, 64, 64))  # z = 0 is a lattice plane
    idx = np.random.default_rng(2).integers(0, 64, size=(4000, 3))
    exact = winding_number(np.asarray(mesh.triangles, float), lat.points(idx) + _RAY_SHIFT * lat.h)
    fast = open_winding_number(mesh, lat, idx)
    np.testing.assert_allclose(fast, exact, atol=1e-9)
    assert np.ptp(exact) > 0.9  # the sample holds inside and outside points


def test_caps_close_the_mesh():
    mesh = _damaged_meshes()["holes and flipped faces"]
    closed = np.concatenate([np.asarray(mesh.triangles, float), boundary_caps(mesh)])
    # every edge is used as often in each direction
    edges = np.concatenate([closed[:, [0, 1]], closed[:, [1, 2]], closed[:, [2, 0]]]).round(12)
    fwd = {tuple(e.ravel()) for e in edges}
    counts = {}
    for e in edges:
        key, back = tuple(e.ravel()), tuple(e[::-1].ravel())
        counts[key] = counts.get(key, 0) + 1
        counts[back] = counts.get(back, 0) - 1
    assert fwd and all(c == 0 for c in counts.values())
    assert len(boundary_caps(trimesh.creation.icosphere(subdivisions=2))) == 0


def test_a_sphere_with_holes_fills_as_the_closed_sphere():
    closed = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    holey = _holey_sphere(np.random.default_rng(3), holes=60)
    lat = Lattice(origin=np.array([-0.35, -0.35, -0.35]), h=0.7 / 47, shape=(48, 48, 48))
    a, b = inside_mask(holey, lat), inside_mask(closed, lat)
    assert a.sum() == pytest.approx(b.sum(), rel=0.01)
    assert np.mean(a != b) < 0.002
