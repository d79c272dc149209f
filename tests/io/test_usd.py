"""USD export: what a DCC opening the shot stage sees."""

from __future__ import annotations

import numpy as np
import pytest

from mpmfx.io import usd as usdio
from mpmfx.io.usd import ColliderSample, MeshSample, PointsSample, UsdShotWriter, validate_stage
from mpmfx.io.vdb import VdbGrid, write_vdb

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom, UsdVol  # noqa: E402

FPS = 24.0
FRAMES = range(11, 16)  # 5 frames; not starting at 0 or 1 on purpose


def _points(frame: int) -> PointsSample:
    rng = np.random.default_rng(frame)
    n = 50 + frame  # particle count changes per frame (emission)
    return PointsSample(
        positions=rng.random((n, 3), dtype=np.float32),
        velocities=rng.standard_normal((n, 3)).astype(np.float32),
        widths=rng.uniform(0.01, 0.03, n).astype(np.float32),
        ids=np.arange(n, dtype=np.int64) * 3,
        primvars={"material": (np.arange(n) % 2).astype(np.int32), "Jp": rng.random(n, dtype=np.float32)},
    )


def _mesh(frame: int) -> MeshSample:
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32) * (1 + 0.1 * frame)
    tris = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int32)
    return MeshSample(
        pts,
        tris,
        normals=pts / np.maximum(np.linalg.norm(pts, axis=1, keepdims=True), 1e-6),
        velocities=np.full((4, 3), 0.1, np.float32),
    )


def _collider(frame: int) -> ColliderSample:
    xform = np.eye(4)
    xform[:3, 3] = (0.0, 0.1 * frame, 0.0)  # column-vector convention: translation in the last column
    pts = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float32)
    return ColliderSample("paddle", pts, np.array([[0, 1, 2], [0, 2, 3]]), xform)


def _vdb(path) -> None:
    phi = np.linspace(-0.2, 0.2, 8**3, dtype=np.float32).reshape(8, 8, 8)
    write_vdb(path, [VdbGrid("surface", phi, (0, 0, 0), 0.05, background=0.15)], metadata={})


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    root = tmp_path_factory.mktemp("usd") / "shot.usda"
    writer = UsdShotWriter(root, fps=FPS, start_frame=FRAMES[0], end_frame=FRAMES[-1])
    for f in FRAMES:
        _vdb(root.parent / "vdb" / f"{f:04d}.vdb")
        writer.write_frame(
            f,
            points={"jelly": _points(f)},
            meshes={"jelly": _mesh(f)},
            volumes={"jelly": {"surface": f"vdb/{f:04d}.vdb"}},
            colliders=[_collider(f)],
        )
    writer.finalize(FRAMES, camera={"position": (0.0, 1.0, 5.0), "look_at": (0.0, 0.5, 0.0), "focal_length": 50.0})
    return root, writer


def test_one_binary_layer_per_frame(shot):
    root, writer = shot
    files = sorted(p.name for p in (root.parent / "frames").iterdir() if not p.name.endswith(".b2"))  # (checksums)
    assert files == [f"{f:04d}.usdc" for f in FRAMES]
    assert all(writer.frame_path(f).read_bytes()[:8] == b"PXR-USDC" for f in FRAMES)


def test_stage_metadata(shot):
    root, _ = shot
    stage = Usd.Stage.Open(str(root))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == FPS
    assert stage.GetFramesPerSecond() == FPS
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (FRAMES[0], FRAMES[-1])
    assert stage.GetDefaultPrim().GetPath() == "/World"


def test_points_mesh_and_primvars_equal_at_every_time_code(shot):
    root, _ = shot
    stage = Usd.Stage.Open(str(root))
    points = UsdGeom.Points(stage.GetPrimAtPath("/World/jelly/particles"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/jelly/mesh"))
    material = UsdGeom.PrimvarsAPI(points).GetPrimvar("material")
    assert material.GetInterpolation() == UsdGeom.Tokens.vertex
    for f in FRAMES:
        want, want_mesh = _points(f), _mesh(f)
        np.testing.assert_array_equal(np.array(points.GetPointsAttr().Get(f)), want.positions)
        np.testing.assert_array_equal(np.array(points.GetVelocitiesAttr().Get(f)), want.velocities)
        np.testing.assert_array_equal(np.array(points.GetIdsAttr().Get(f)), want.ids)
        np.testing.assert_array_equal(np.array(material.Get(f)), want.primvars["material"])
        np.testing.assert_array_equal(np.array(points.GetWidthsAttr().Get(f)), want.widths)
        np.testing.assert_array_equal(np.array(mesh.GetPointsAttr().Get(f)), want_mesh.points)
        np.testing.assert_array_equal(
            np.array(mesh.GetFaceVertexIndicesAttr().Get(f)), want_mesh.face_vertex_indices.reshape(-1)
        )
        extent = np.array(points.GetExtentAttr().Get(f))
        # The extent bounds the spheres, not just their centres (renderers cull with it).
        r = want.widths.max() / 2
        assert (extent[0] <= want.positions.min(0) - r + 1e-6).all()
        assert (extent[1] >= want.positions.max(0) + r - 1e-6).all()
    assert points.GetWidthsInterpolation() == UsdGeom.Tokens.vertex


def test_objects_that_come_and_go_have_no_points_when_absent(tmp_path):
    writer = UsdShotWriter(tmp_path / "s.usda", fps=FPS, start_frame=1, end_frame=3)
    one = np.zeros((1, 3), np.float32)
    writer.write_frame(1, points={"a": PointsSample(one, widths=0.1)})
    writer.write_frame(2, points={"a": PointsSample(one, widths=0.1), "b": PointsSample(one, widths=0.2)})
    writer.write_frame(3, points={"b": PointsSample(one, widths=0.2)})
    stage = Usd.Stage.Open(str(writer.finalize([1, 2, 3])))
    a = UsdGeom.Points(stage.GetPrimAtPath("/World/a/particles"))
    b = UsdGeom.Points(stage.GetPrimAtPath("/World/b/particles"))
    assert [a.GetPointsAttr().Get(t) is None for t in (1, 2, 3)] == [False, False, True]
    assert [b.GetPointsAttr().Get(t) is None for t in (1, 2, 3)] == [True, False, False]
    # A scalar width is one shared diameter: constant interpolation.
    assert b.GetWidthsInterpolation() == UsdGeom.Tokens.constant
    assert list(b.GetWidthsAttr().Get(2)) == [pytest.approx(0.2)]


def test_volume_fields_point_at_each_frames_vdb(shot):
    root, _ = shot
    stage = Usd.Stage.Open(str(root))
    volume = UsdVol.Volume(stage.GetPrimAtPath("/World/jelly/volume"))
    asset = UsdVol.OpenVDBAsset(stage.GetPrimAtPath(volume.GetFieldPath("surface")))
    assert asset.GetFieldNameAttr().Get() == "surface"
    assert asset.GetFieldClassAttr().Get() == UsdVol.Tokens.levelSet
    for f in FRAMES:
        resolved = asset.GetFilePathAttr().Get(f).resolvedPath
        assert resolved == str(root.parent / "vdb" / f"{f:04d}.vdb")


def test_collider_moves_with_its_transform(shot):
    root, _ = shot
    stage = Usd.Stage.Open(str(root))
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/World/colliders/paddle"))
    for f in FRAMES:
        world = np.array(xf.ComputeLocalToWorldTransform(f))
        corner = np.array([1.0, 0.0, 1.0, 1.0]) @ world  # USD: row vector times matrix
        np.testing.assert_allclose(corner[:3], [1.0, 0.1 * f, 1.0], atol=1e-9)


def test_camera_looks_at_its_target(shot):
    root, _ = shot
    stage = Usd.Stage.Open(str(root))
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/camera")).GetCamera(FRAMES[0])
    frustum = cam.frustum
    direction = np.array(frustum.ComputeViewDirection())
    want = np.array([0.0, -0.5, -5.0]) / np.linalg.norm([0.0, -0.5, -5.0])
    np.testing.assert_allclose(direction, want, atol=1e-6)
    # 50 mm lens on a 36 mm back: horizontal field of view 2 atan(18/50).
    fov = np.degrees(2 * np.arctan(18 / 50))
    assert cam.GetFieldOfView(cam.FOVHorizontal) == pytest.approx(fov, rel=1e-5)


def test_validators_find_no_errors(shot):
    root, _ = shot
    assert validate_stage(root) == []


def test_validators_report_a_missing_vdb(shot, tmp_path):
    root, _ = shot
    writer = UsdShotWriter(tmp_path / "bad.usda", fps=FPS, start_frame=1, end_frame=1)
    writer.write_frame(1, volumes={"jelly": {"surface": "vdb/missing.vdb"}})
    writer.finalize([1])
    errors = validate_stage(tmp_path / "bad.usda")
    assert any("missing.vdb" in e for e in errors)


def test_unit_and_axis_conversion_happen_once_at_world(tmp_path):
    writer = UsdShotWriter(tmp_path / "cm.usda", fps=FPS, start_frame=1, end_frame=1, up_axis="Z", meters_per_unit=0.01)
    writer.write_frame(1, points={"p": PointsSample(np.array([[0.0, 1.0, 0.0]], np.float32))})
    stage = Usd.Stage.Open(str(writer.finalize([1])))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/World/p/particles")).ComputeLocalToWorldTransform(1)
    # 1 m up (Y) in the sim is 100 cm up (Z) in the stage.
    np.testing.assert_allclose(np.array(xf.Transform((0.0, 1.0, 0.0))), [0.0, 0.0, 100.0], atol=1e-6)


def test_failed_frame_write_keeps_the_old_frame_and_leaves_no_temp(shot, monkeypatch):
    root, writer = shot
    path = writer.frame_path(FRAMES[0])
    before = path.read_bytes()
    bad = _points(FRAMES[0])
    bad.primvars["label"] = np.array(["a"] * len(bad.positions))
    with pytest.raises(ValueError, match="label"):
        writer.write_frame(FRAMES[0], points={"jelly": bad})

    def crash(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(usdio.os, "replace", crash)
    with pytest.raises(OSError, match="disk full"):
        writer.write_frame(FRAMES[0], points={"jelly": _points(FRAMES[0] + 1)})
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert not [p for p in root.parent.rglob("*") if ".tmp" in p.name]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"points": {"my-jelly": PointsSample(np.zeros((1, 3), np.float32))}}, "valid USD prim name.*my_jelly"),
        ({"points": {"camera": PointsSample(np.zeros((1, 3), np.float32))}}, "reserved"),
        ({"points": {"j": PointsSample(np.zeros((4, 2), np.float32))}}, r"positions: shape \(4, 2\)"),
        (
            {"meshes": {"j": MeshSample(np.zeros((3, 3), np.float32), np.array([[0, 1, 3]]))}},
            r"indices must lie in \[0, 3\)",
        ),
        ({"volumes": {"j": {"surface": "vdb/x.nvdb"}}}, "not a .vdb"),
    ],
)
def test_bad_frame_input_is_rejected_with_the_field_named(tmp_path, kwargs, message):
    writer = UsdShotWriter(tmp_path / "s.usda", fps=FPS, start_frame=1, end_frame=1)
    with pytest.raises(ValueError, match=message):
        writer.write_frame(1, **kwargs)
    assert not writer.frame_path(1).exists()


def test_finalize_names_missing_frames(tmp_path):
    writer = UsdShotWriter(tmp_path / "s.usda", fps=FPS, start_frame=1, end_frame=3)
    writer.write_frame(1, points={"p": PointsSample(np.zeros((1, 3), np.float32))})
    with pytest.raises(ValueError, match="0002.usdc"):
        writer.finalize([1, 2])
    assert not (tmp_path / "s.usda").exists()


def test_importing_the_module_loads_no_pxr_and_a_missing_pxr_says_how_to_install(tmp_path, monkeypatch):
    import subprocess
    import sys

    code = "import sys, mpmfx.io.usd, mpmfx.io.vdb; print('pxr' in sys.modules, 'pyopenvdb' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
    monkeypatch.setitem(sys.modules, "pxr", None)
    writer = UsdShotWriter(tmp_path / "s.usda", fps=FPS, start_frame=1, end_frame=1)
    with pytest.raises(ImportError, match="pip install usd-core"):
        writer.write_frame(1, points={"p": PointsSample(np.zeros((1, 3), np.float32))})


def test_written_files_get_ordinary_permissions(shot, tmp_path):
    # A farm renderer running as another user must be able to read what export wrote.
    root, writer = shot
    reference = tmp_path / "plain.txt"
    reference.write_text("x")
    want = reference.stat().st_mode & 0o777
    for path in (root, writer.topology_path(), writer.manifest_path(), writer.frame_path(FRAMES[0])):
        assert path.stat().st_mode & 0o777 == want, path
