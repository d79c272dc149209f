"""OpenVDB export: what a DCC or renderer reading the file gets back."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from mpmfx import checksum
from mpmfx.io import vdb as vdbio
from mpmfx.io.vdb import GridClass, VdbGrid, read_vdb, write_vdb

VOXEL = 0.05  # metres
RADIUS = 0.4  # metres
BAND = 3 * VOXEL  # narrow-band half width, metres
IJK0 = (-12, -10, -11)
SHAPE = (24, 22, 23)
CENTRE = np.array([0.02, 0.03, -0.01])


def _world_coords() -> np.ndarray:
    """(a, b, c, 3) world positions of the voxel centres, VDB convention (index * voxel)."""
    idx = np.stack(np.meshgrid(*[np.arange(n) + o for n, o in zip(SHAPE, IJK0)], indexing="ij"), -1)
    return idx * VOXEL


def _sphere_grids() -> list[VdbGrid]:
    x = _world_coords()
    phi = (np.linalg.norm(x - CENTRE, axis=-1) - RADIUS).astype(np.float32)
    # Rigid rotation about y at 2 rad/s: a velocity field with a known value everywhere.
    vel = np.zeros(SHAPE + (3,), np.float32)
    vel[..., 0] = 2.0 * x[..., 2]
    vel[..., 2] = -2.0 * x[..., 0]
    vel[phi > 0] = 0.0
    density = np.clip(-phi / BAND, 0.0, 1.0).astype(np.float32)
    return [
        VdbGrid("surface", phi, IJK0, VOXEL, grid_class="level_set", background=BAND),
        VdbGrid("vel", vel, IJK0, VOXEL, grid_class=GridClass.UNKNOWN),
        VdbGrid("density", density, IJK0, VOXEL, grid_class="fog_volume"),
    ]


@pytest.fixture(scope="module")
def sphere_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("vdb") / "0007.vdb"
    grids = _sphere_grids()
    write_vdb(path, grids, metadata={"frame": 7, "time_s": 0.29, "shot": "unit"})
    return path, grids


def test_classes_voxel_size_and_metadata_round_trip(sphere_file):
    path, _ = sphere_file
    info = read_vdb(path)
    assert info["metadata"] == {"frame": 7, "time_s": pytest.approx(0.29), "shot": "unit"}
    grids = info["grids"]
    assert set(grids) == {"surface", "vel", "density"}
    assert grids["surface"]["class"] is GridClass.LEVEL_SET
    assert grids["surface"]["background"] == pytest.approx(BAND)
    assert grids["density"]["class"] is GridClass.FOG_VOLUME
    assert grids["vel"]["vector_type"] == "contravariant relative"
    for g in grids.values():
        assert g["voxel_size"] == pytest.approx((VOXEL,) * 3)


def test_level_set_keeps_the_band_and_signs_the_rest(sphere_file):
    path, grids = sphere_file
    phi = grids[0].values
    info = read_vdb(path, with_values=True)["grids"]["surface"]
    # Only the narrow band is stored: what makes a level set cheap on disk.
    assert info["active_voxel_count"] == int((np.abs(phi) < BAND).sum())
    vdb = vdbio.import_pyopenvdb()
    grid = vdb.read(str(path), "surface")
    back = np.zeros(SHAPE, np.float32)
    grid.copyToArray(back, ijk=IJK0)
    # Inside the band exact values; outside, +-band with the sign of the true distance.
    np.testing.assert_array_equal(back, np.clip(phi, -BAND, BAND))


def test_world_position_of_the_zero_crossing(sphere_file):
    path, _ = sphere_file
    vdb = vdbio.import_pyopenvdb()
    grid = vdb.read(str(path), "surface")
    acc = grid.getConstAccessor()
    # Voxel nearest the sphere's centre must be deep inside; one on the +x surface near zero.
    centre_ijk = tuple(int(v) for v in np.round(CENTRE / VOXEL))
    assert acc.getValue(centre_ijk) == pytest.approx(-BAND)
    world = np.array(grid.transform.indexToWorld(centre_ijk))
    np.testing.assert_allclose(world, np.round(CENTRE / VOXEL) * VOXEL, atol=1e-6)


def test_vectors_and_density_round_trip(sphere_file):
    path, grids = sphere_file
    info = read_vdb(path, with_values=True)["grids"]
    for grid in grids[1:]:
        got = info[grid.name]
        lo = np.array(got["ijk0"]) - np.array(IJK0)
        block = grid.values[tuple(slice(l, l + n) for l, n in zip(lo, got["values"].shape[:3]))]
        np.testing.assert_array_equal(got["values"], block)
        # Everything outside the active bounding box is background (zero) in the source.
        assert np.abs(grid.values).sum() == pytest.approx(np.abs(block).sum(), rel=1e-6)


@pytest.mark.skipif(shutil.which("vdb_print") is None, reason="vdb_print (libopenvdb-tools) not installed")
def test_vdb_print_reads_the_file(sphere_file):
    path, _ = sphere_file
    out = subprocess.run(["vdb_print", "-l", str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "surface" in out.stdout and "vel" in out.stdout and "density" in out.stdout
    assert "class: level set" in out.stdout


def test_failed_write_leaves_no_file_and_keeps_the_old_one(tmp_path, monkeypatch):
    path = tmp_path / "0001.vdb"
    write_vdb(path, _sphere_grids()[:1], metadata={})
    before = path.read_bytes()
    bad = _sphere_grids()
    bad[2].values[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="density.*NaN"):
        write_vdb(path, bad, metadata={})

    def crash(*args, **kwargs):
        raise OSError("disk full")

    import mpmfx.cache

    monkeypatch.setattr(mpmfx.cache.os, "replace", crash)
    with pytest.raises(OSError, match="disk full"):
        write_vdb(path, _sphere_grids(), metadata={})
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [".0001.vdb.b2", "0001.vdb"]  # and its checksum
    assert checksum.recorded(path) == checksum.digest(path)  # still the old file's


@pytest.mark.parametrize(
    "change, message",
    [
        ({"background": 0.0}, "narrow-band"),
        ({"voxel_size": -1.0}, "voxel_size"),
        ({"values": np.zeros((4, 4), np.float32)}, "shape"),
        ({"grid_class": "smoke"}, "grid_class"),
    ],
)
def test_bad_grids_are_rejected_with_the_field_named(tmp_path, change, message):
    fields = dict(
        name="surface",
        values=np.ones((4, 4, 4), np.float32),
        ijk0=(0, 0, 0),
        voxel_size=0.1,
        grid_class="level_set",
        background=0.3,
    )
    fields.update(change)
    with pytest.raises(ValueError, match=message):
        write_vdb(tmp_path / "x.vdb", [VdbGrid(**fields)], metadata={})
    assert not (tmp_path / "x.vdb").exists()


def test_metadata_of_unsupported_type_is_rejected(tmp_path):
    with pytest.raises(ValueError, match="'params'.*str, int or float"):
        write_vdb(tmp_path / "x.vdb", _sphere_grids()[:1], metadata={"params": {"a": 1}})


def test_missing_pyopenvdb_says_how_to_install(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pyopenvdb", None)
    with pytest.raises(ImportError, match="apt-get install python3-openvdb"):
        write_vdb(tmp_path / "x.vdb", _sphere_grids()[:1], metadata={})


def test_half_float_grids_are_smaller_and_close(tmp_path):
    """Export's choice: half floats on disk, ~5e-4 relative, a quarter less disk."""
    import numpy as np

    from mpmfx.io.vdb import VdbGrid, read_vdb, write_vdb

    rng = np.random.default_rng(0)
    x = np.linspace(-1, 1, 40, dtype=np.float32)
    phi = (np.sqrt(x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2) - 0.6).astype(np.float32)
    vel = rng.normal(size=phi.shape + (3,)).astype(np.float32)
    sizes = {}
    for half in (False, True):
        grids = [
            VdbGrid("surface", phi, (0, 0, 0), 0.05, "level_set", 0.15, half=half),
            VdbGrid("vel", vel, (0, 0, 0), 0.05, "unknown", 0.0, half=half),
        ]
        path = write_vdb(tmp_path / f"h{int(half)}.vdb", grids, metadata={"frame": 1})
        sizes[half] = path.stat().st_size
        got = read_vdb(path, with_values=True)["grids"]["vel"]["values"]
        assert np.allclose(got, vel[tuple(slice(0, s) for s in got.shape[:3])], rtol=1e-3, atol=1e-3)
    assert sizes[True] < 0.7 * sizes[False]


def test_leaf_grids_write_what_the_dense_blocks_of_the_same_leaves_write(tmp_path):
    """The export writes the surface stage's leaves without a dense block over their bounding
    box: a reader gets the same voxels (values, active set, classes) either way."""
    from mpmfx.surface.params import SparseLevelSet

    corners = np.stack(np.meshgrid(*[np.arange(-24, 24, 8)] * 3, indexing="ij"), -1).reshape(-1, 3)
    idx = corners[:, None, None, None, :] + np.stack(np.meshgrid(*[np.arange(8)] * 3, indexing="ij"), -1)
    phi = (np.linalg.norm(idx * VOXEL - CENTRE, axis=-1) - 0.9).astype(np.float32)  # (216, 8, 8, 8)
    near, inside = np.abs(phi).min(axis=(1, 2, 3)) < BAND, phi.max(axis=(1, 2, 3)) <= -BAND
    vel = np.where(phi[..., None] < BAND, idx * 0.1, 0).astype(np.float16)
    fog = np.clip(-phi / BAND, 0, 1).astype(np.float16)
    both = np.flatnonzero(inside)[0]  # a leaf both stored and listed inside: the stored values win
    near[both], fog[both] = True, 0.5
    sparse = SparseLevelSet(
        corners[near], np.clip(phi[near], -BAND, BAND), vel[near], corners[inside], VOXEL, BAND, fog[near]
    )
    ls = sparse.to_dense()
    ijk0 = tuple(int(i) for i in ls.ijk0)
    dense = [
        VdbGrid("surface", ls.values, ijk0, VOXEL, "level_set", BAND, half=True),
        VdbGrid("vel", sparse.velocity_dense(ls.ijk0, ls.values.shape), ijk0, VOXEL, "unknown", 0.0, half=True),
        VdbGrid("density", sparse.density_dense(ls.ijk0, ls.values.shape), ijk0, VOXEL, "fog_volume", 0.0, half=True),
    ]
    leaves = [
        vdbio.LeafGrid("surface", corners[near], phi[near], VOXEL, "level_set", BAND, half=True),
        vdbio.LeafGrid("vel", corners[near], vel[near], VOXEL, "unknown", 0.0, half=True),
        vdbio.LeafGrid("density", corners[near], fog[near], VOXEL, "fog_volume", 0.0, True, corners[inside], 1.0),
    ]
    write_vdb(tmp_path / "dense.vdb", dense, metadata={})
    write_vdb(tmp_path / "leaves.vdb", leaves, metadata={})
    a = read_vdb(tmp_path / "dense.vdb", with_values=True)["grids"]
    b = read_vdb(tmp_path / "leaves.vdb", with_values=True)["grids"]
    assert a["density"]["active_voxel_count"] > fog[near].astype(bool).sum()  # the inside leaves are there
    for name in ("surface", "vel", "density"):
        values_a, values_b = a[name].pop("values"), b[name].pop("values")
        assert a[name] == b[name], name
        np.testing.assert_array_equal(values_a, values_b)
