"""Emitters (geometry/emitters.py): the emitted volume per second is the rate; emission is
deterministic; particles stay in the source; an open mesh is refused."""

import numpy as np
import pytest
import trimesh

from mpmfx.geometry.emitters import EmitterError, emission_count, emit, shape_mesh, source_points
from mpmfx.geometry.mesh import transform_mesh

DOMAIN = dict(origin=(-0.5, -0.5, -0.5), size=1.0, grid_n=32)
VP = (1.0 / 32) ** 3 / 8  # m^3 a particle at ppc 8


def _emit(shape="box", rate=0.01, start=0.2, end=1.2, seed=0, velocity=(0.0, -1.0, 0.0), **kw):
    mesh = transform_mesh(shape_mesh(shape, size=(0.1, 0.06, 0.1), radius=0.06), translate=(0.1, 0.2, 0.0))
    pts, h = source_points(mesh, ppc=8, **DOMAIN)
    out = emit(pts, h, particle_volume=VP, rate=rate, velocity=velocity, start=start, end=end, seed=seed)
    return mesh, pts, out


@pytest.mark.parametrize("shape", ["box", "sphere"])
@pytest.mark.parametrize("rate", [0.004, 0.013])
def test_the_emitted_volume_per_second_is_the_rate(shape, rate):
    """Over the emission and over any whole second inside it, volume emitted / time = rate,
    to one particle's volume (the count is whole particles)."""
    _, _, out = _emit(shape, rate=rate, start=0.2, end=2.2)
    assert len(out.birth) * out.volume == pytest.approx(rate * 2.0, abs=out.volume)
    for t in (0.2, 0.7, 1.1):
        inside = np.count_nonzero((out.birth >= t) & (out.birth < t + 1.0))
        assert inside * out.volume == pytest.approx(rate, abs=out.volume)
    density = 997.0  # kg/m^3 (any): the emitted mass per second is rate x density
    assert len(out.birth) * out.volume * density / 2.0 == pytest.approx(rate * density, rel=1e-3)
    assert np.all(np.diff(out.birth) > 0) and out.birth[0] >= 0.2 and out.birth[-1] <= 2.2


def test_emission_is_deterministic_and_the_seed_moves_only_the_jitter():
    _, _, a = _emit(seed=3)
    _, _, b = _emit(seed=3)
    _, _, c = _emit(seed=4)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.birth, c.birth)
    assert not np.array_equal(a.points, c.points)


def test_particles_start_inside_the_source_downstream_first():
    mesh, pts, out = _emit(velocity=(0.0, -2.0, 0.0))
    h = (1.0 / 32) / 2
    lo, hi = mesh.bounds
    assert np.all(out.points >= lo - 0.25 * h - 1e-9) and np.all(out.points <= hi + 0.25 * h + 1e-9)
    fill = out.points[: len(pts)]  # the first fill: the lowest layer (downstream: -y) first
    assert fill[0, 1] < fill[-1, 1]
    assert np.all(np.diff(fill[:, 1]) >= -0.5 * h - 1e-9)  # (a quarter spacing of jitter either way)
    assert emission_count(0.01, 1.0, VP) == len(out.birth)


def test_an_open_mesh_is_not_a_source():
    box = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    box.update_faces(np.arange(len(box.faces)) != 0)  # one triangle off: a hole
    with pytest.raises(EmitterError, match="not closed"):
        source_points(box, ppc=8, **DOMAIN)
