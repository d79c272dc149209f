from pathlib import Path

import numpy as np
import pytest
import trimesh

from mpmfx.geometry.mesh import MeshError, check_in_domain, load_mesh, transform_mesh

BOX = trimesh.creation.box(extents=(0.2, 0.4, 0.6))


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl", ".glb"])
def test_trimesh_formats_round_trip(tmp_path, suffix):
    path = tmp_path / f"box{suffix}"
    BOX.export(path)
    mesh = load_mesh(path)
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(0.2 * 0.4 * 0.6, rel=1e-6)
    np.testing.assert_allclose(mesh.extents, (0.2, 0.4, 0.6), rtol=1e-6)


def _write_usda(path: Path, mesh, *, meters_per_unit=1.0, translate=(0, 0, 0), quads=False, up_axis="Y", scheme="none"):
    from pxr import Gf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up_axis == "Z" else UsdGeom.Tokens.y)
    xf = UsdGeom.Xform.Define(stage, "/world")
    xf.AddTranslateOp().Set(Gf.Vec3d(*translate))
    geom = UsdGeom.Mesh.Define(stage, "/world/box")
    if scheme:  # "none": a polygon mesh, as DCCs export one; None: unauthored (USD's default, catmullClark)
        geom.CreateSubdivisionSchemeAttr(scheme)
    if quads:  # a unit cube as 6 quads: exercises n-gon triangulation
        v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
        f = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
        geom.CreatePointsAttr([Gf.Vec3f(*p) for p in v])
        geom.CreateFaceVertexCountsAttr([4] * 6)
        geom.CreateFaceVertexIndicesAttr([i for q in f for i in q])
    else:
        geom.CreatePointsAttr([Gf.Vec3f(*p) for p in mesh.vertices])
        geom.CreateFaceVertexCountsAttr([3] * len(mesh.faces))
        geom.CreateFaceVertexIndicesAttr([int(i) for i in mesh.faces.ravel()])
    stage.GetRootLayer().Save()


def test_usda_applies_transform_and_meters_per_unit(tmp_path):
    path = tmp_path / "box.usda"
    _write_usda(path, BOX, meters_per_unit=0.01, translate=(100, 0, 0))  # centimetres
    mesh = load_mesh(path)
    np.testing.assert_allclose(mesh.extents, (0.002, 0.004, 0.006), rtol=1e-5)
    np.testing.assert_allclose(mesh.bounds.mean(0), (1.0, 0, 0), atol=1e-6)


def test_a_z_up_stage_stands_up_in_our_y_up_world(tmp_path):
    # Blender's USD export is Z-up: a box 0.6 m tall along its z, 1 m above the ground, must
    # stand 0.6 m tall along our y, 1 m up, wound outward still
    path = tmp_path / "blender.usda"
    _write_usda(path, BOX, translate=(0.5, 0, 1.0), up_axis="Z")
    mesh = load_mesh(path)
    np.testing.assert_allclose(mesh.extents, (0.2, 0.6, 0.4), rtol=1e-5)
    np.testing.assert_allclose(mesh.bounds.mean(0), (0.5, 1.0, 0.0), atol=1e-6)
    assert mesh.is_watertight and mesh.volume == pytest.approx(0.2 * 0.4 * 0.6, rel=1e-5)


def test_usda_quads_are_triangulated_into_a_closed_cube(tmp_path):
    path = tmp_path / "quads.usda"
    _write_usda(path, None, quads=True)
    mesh = load_mesh(path)
    assert len(mesh.faces) == 12 and mesh.is_watertight
    assert abs(mesh.volume) == pytest.approx(1.0)


def test_usd_prim_path_selects_and_errors(tmp_path):
    path = tmp_path / "box.usda"
    _write_usda(path, BOX)
    assert len(load_mesh(path, prim_path="/world/box").faces) == 12
    with pytest.raises(MeshError, match="/nope.*not found"):
        load_mesh(path, prim_path="/nope")


def test_warp_bunny_loads_from_usd():
    import warp

    path = Path(warp.__file__).parent / "examples" / "assets" / "bunny.usd"
    mesh = load_mesh(path)
    assert len(mesh.faces) > 1000
    assert 0 < mesh.extents.min() < mesh.extents.max()


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda d: d / "missing.obj", "no such file"),
        (lambda d: _text(d / "junk.usda", "this is not usd"), "cannot be opened as a USD stage"),
        (lambda d: _text(d / "junk.glb", "garbage"), "cannot be read as a mesh"),
        (lambda d: _text(d / "points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"), "no triangles"),
        (lambda d: _text(d / "flat.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n"), "flat"),
        (lambda d: _text(d / "mesh.xyz", "1 2 3"), "unsupported format"),
        (
            lambda d: _text(
                d / "far.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1e30\nf 1 2 3\nf 1 2 4\nf 2 3 4\nf 1 3 4\n"
            ),
            "absurdly far out",
        ),
    ],
)
def test_bad_files_raise_mesh_error_naming_file(tmp_path, make, match):
    path = make(tmp_path)
    with pytest.raises(MeshError, match=match) as info:
        load_mesh(path)
    assert path.name in str(info.value)
    assert isinstance(info.value, ValueError)


def _text(path, text):
    path.write_text(text)
    return path


def test_transform_scales_rotates_then_translates():
    out = transform_mesh(BOX, scale=2.0, rotate_deg=(0, 0, 90), translate=(1, 0, 0))
    # 0.2 x 0.4 scaled to 0.4 x 0.8, then turned 90 deg about z: 0.8 x 0.4.
    np.testing.assert_allclose(out.extents, (0.8, 0.4, 1.2), atol=1e-9)
    np.testing.assert_allclose(out.bounds.mean(0), (1, 0, 0), atol=1e-9)
    assert BOX.extents[0] == pytest.approx(0.2)  # input untouched
    with pytest.raises(MeshError, match="positive"):
        transform_mesh(BOX, scale=(1, -1, 1))


def test_check_in_domain_messages_say_what_to_change():
    check_in_domain(BOX, origin=(-0.5, -0.5, -0.5), size=1.0, name="box")
    with pytest.raises(MeshError, match=r"box: .*larger than the domain.*scale it by at most 0.5"):
        check_in_domain(BOX, origin=(0, 0, 0), size=0.3, name="box")
    with pytest.raises(MeshError, match=r"outside the domain.*translate it by \(0.1, 0.2, 0.3\)"):
        check_in_domain(BOX, origin=(0, 0, 0), size=1.0, name="box")


def _box_prim(stage, path, *, translate=(0, 0, 0)):
    from pxr import Gf, UsdGeom

    geom = UsdGeom.Mesh.Define(stage, path)
    geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    geom.CreatePointsAttr([Gf.Vec3f(*p) for p in BOX.vertices])
    geom.CreateFaceVertexCountsAttr([3] * len(BOX.faces))
    geom.CreateFaceVertexIndicesAttr([int(i) for i in BOX.faces.ravel()])
    if any(translate):
        geom.AddTranslateOp().Set(Gf.Vec3d(*translate))
    return geom


def test_usd_loads_what_a_renderer_draws(tmp_path):
    # a production-style stage: instanceable references, a PointInstancer, a proxy double of
    # the render geometry, a guide and a hidden part; only the drawn boxes come in, each where
    # it is drawn
    from pxr import Gf, Sdf, Usd, UsdGeom

    path = tmp_path / "set.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Xform.Define(stage, "/world")
    _box_prim(stage, "/protos/crate/geo")
    stage.GetPrimAtPath("/protos").SetSpecifier(Sdf.SpecifierClass)  # not drawn itself
    for i, x in enumerate((2.0, 4.0)):  # two instanceable references to the crate
        ref = UsdGeom.Xform.Define(stage, f"/world/crate{i}")
        ref.AddTranslateOp().Set(Gf.Vec3d(x, 0, 0))
        ref.GetPrim().GetReferences().AddInternalReference("/protos/crate")
        ref.GetPrim().SetInstanceable(True)
    inst = UsdGeom.PointInstancer.Define(stage, "/world/scatter")
    inst.AddTranslateOp().Set(Gf.Vec3d(0, 0, 10.0))
    proto = _box_prim(stage, "/world/scatter/protos/box", translate=(0, 1.0, 0))  # its own transform counts once
    inst.CreatePrototypesRel().SetTargets([proto.GetPath()])
    inst.CreateProtoIndicesAttr([0, 0, 0, 0])
    inst.CreatePositionsAttr([Gf.Vec3f(-3, 0, 0), Gf.Vec3f(-5, 0, 0), Gf.Vec3f(9, 9, 9), Gf.Vec3f(-7, 0, 0)])
    inst.CreateInvisibleIdsAttr([2])  # the third instance hidden: the fourth still where it is
    _box_prim(stage, "/world/proxy", translate=(9, 9, 9)).CreatePurposeAttr(UsdGeom.Tokens.proxy)
    _box_prim(stage, "/world/guide", translate=(9, 9, 9)).CreatePurposeAttr(UsdGeom.Tokens.guide)
    _box_prim(stage, "/world/hidden", translate=(9, 9, 9)).MakeInvisible()
    stage.GetRootLayer().Save()
    mesh = load_mesh(path)
    parts = mesh.split(only_watertight=True)
    centres = sorted(tuple(np.round(p.bounds.mean(0), 6)) for p in parts)
    assert centres == [(-7, 1, 10), (-5, 1, 10), (-3, 1, 10), (2, 0, 0), (4, 0, 0)]
    assert all(p.volume == pytest.approx(0.2 * 0.4 * 0.6, rel=1e-5) for p in parts)


@pytest.mark.parametrize("scheme", [None, "catmullClark"])
def test_a_subdivision_cage_loads_as_its_limit_surface(tmp_path, scheme):
    # a unit cube's cage, subdivided as a renderer draws it: a rounded blob a third of its
    # volume, 0.08 inside each face (the limit surface), not the cube
    path = tmp_path / "subd.usda"
    _write_usda(path, None, quads=True, scheme=scheme)
    if scheme is None:
        warning = r"subd\.usda: /world/box: no subdivisionScheme.*subdivisionScheme = \"none\""
        with pytest.warns(UserWarning, match=warning):
            mesh = load_mesh(path)
    else:
        mesh = load_mesh(path)
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(0.328, abs=0.01)
    np.testing.assert_allclose(mesh.bounds, [[0.075] * 3, [0.925] * 3], atol=0.006)


def test_creases_keep_a_subdivision_cages_edges(tmp_path):
    # the top face's four edges creased for good, a corner of the bottom sharp: the top stays a
    # flat face at z = 1 out to near the cage's edges (its outline a crease curve, round at the
    # corners: two creased edges meet there), and that corner where it was (the same vertices
    # as Blender's OpenSubdiv, mpmfx.geometry.subdivide); creased for one level only (sharpness
    # 0.5) the top rounds as without creases (0.925 high)
    from pxr import Usd, UsdGeom

    def load(sharpness):
        path = tmp_path / f"crease{sharpness}.usda"
        _write_usda(path, None, quads=True, scheme="catmullClark")
        stage = Usd.Stage.Open(str(path))
        geom = UsdGeom.Mesh(stage.GetPrimAtPath("/world/box"))
        geom.CreateCreaseIndicesAttr([1, 3, 7, 5, 1])  # one chain round the top (z = 1) face
        geom.CreateCreaseLengthsAttr([5])
        geom.CreateCreaseSharpnessesAttr([sharpness])
        geom.CreateCornerIndicesAttr([0])
        geom.CreateCornerSharpnessesAttr([10.0])
        stage.GetRootLayer().Save()
        return load_mesh(path)

    sharp = load(10.0)
    top = sharp.vertices[np.isclose(sharp.vertices[:, 2], 1.0)]
    assert len(top) > 20 and np.all(top[:, :2].min(0) < 0.05) and np.all(top[:, :2].max(0) > 0.95)
    assert np.isclose(np.linalg.norm(sharp.vertices, axis=1), 0.0).any()  # the sharp corner stays
    assert sharp.vertices[:, 2].max() == pytest.approx(1.0)
    assert load(0.5).vertices[:, 2].max() < 0.97
    with pytest.raises(MeshError, match=r"bad\.usda: /world/box: creaseSharpnesses holds 2 values for 1 creases of 4"):
        path = tmp_path / "bad.usda"
        _write_usda(path, None, quads=True, scheme="catmullClark")
        stage = Usd.Stage.Open(str(path))
        geom = UsdGeom.Mesh(stage.GetPrimAtPath("/world/box"))
        geom.CreateCreaseIndicesAttr([1, 3, 7, 5, 1])
        geom.CreateCreaseLengthsAttr([5])
        geom.CreateCreaseSharpnessesAttr([1.0, 2.0])
        stage.GetRootLayer().Save()
        load_mesh(path)


def test_hole_faces_are_not_loaded(tmp_path):
    from pxr import Usd, UsdGeom

    path = tmp_path / "holes.usda"
    _write_usda(path, None, quads=True)
    stage = Usd.Stage.Open(str(path))
    UsdGeom.Mesh(stage.GetPrimAtPath("/world/box")).CreateHoleIndicesAttr([1])  # the x = 1 face
    stage.GetRootLayer().Save()
    mesh = load_mesh(path)
    assert len(mesh.faces) == 10 and not mesh.is_watertight
    assert not np.any(np.all(np.isclose(mesh.triangles[:, :, 0], 1.0), axis=1))


# Runs inside Blender (its own process, as the loader's child): a scene an artist would save.
BLEND_SCENE = """
import sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(2, 0, 0.5))  # Blender is Z up: standing on the ground
array = bpy.context.object.modifiers.new("array", "ARRAY")
array.count, array.relative_offset_displace = 2, (0, 2, 0)
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(-3, 0, 3))
bpy.context.object.hide_render = True
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 5))
sub = bpy.context.object.modifiers.new("subd", "SUBSURF")
sub.levels, sub.render_levels = 0, 2
crates = bpy.data.collections.new("Crates")  # the second cube alone in a collection
bpy.context.scene.collection.children.link(crates)
crates.objects.link(bpy.context.object)
bpy.context.scene.collection.objects.unlink(bpy.context.object)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[1])
bpy.ops.export_scene.fbx(filepath=sys.argv[2], use_mesh_modifiers=False)
bpy.ops.export_scene.gltf(filepath=sys.argv[3], export_draco_mesh_compression_enable=True)
"""


@pytest.fixture(scope="module")
def blender_files(tmp_path_factory):
    import subprocess
    import sys

    from mpmfx.blender import bpy_available

    if not bpy_available():
        pytest.fail("bpy (Blender as a module) is part of the test set-up: bash setup.sh test installs it")
    folder = tmp_path_factory.mktemp("blend")
    blend, fbx, glb = folder / "scene.blend", folder / "scene.fbx", folder / "draco.glb"
    res = subprocess.run(
        [sys.executable, "-c", BLEND_SCENE, str(blend), str(fbx), str(glb)], capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    return blend, fbx, glb


def _parts(mesh):
    return sorted(
        ((tuple(np.round(p.bounds.mean(0), 3)), round(float(p.volume), 3)) for p in mesh.split(only_watertight=False)),
        key=lambda r: r[0],
    )


def test_a_blend_file_loads_as_cycles_renders_it(blender_files):
    # Y up, in metres; the array's copy too; the sphere hidden from renders left out; the cube
    # with a subdivision at render levels 2 (viewport 0) comes in rounded
    parts = _parts(load_mesh(blender_files[0]))
    assert [c for c, _ in parts] == [(0.0, 5.0, 0.0), (2.0, 0.5, -2.0), (2.0, 0.5, 0.0)]
    assert parts[1][1] == parts[2][1] == pytest.approx(1.0)
    assert 0.25 < parts[0][1] < 0.4


def test_prim_path_takes_one_object_of_a_blend_file(blender_files, tmp_path):
    # "Cube" with its array's copy, not the other cube; the collection "Crates" its one cube; an
    # unknown name lists the file's surfaces
    assert [c for c, _ in _parts(load_mesh(blender_files[0], prim_path="Cube"))] == [(2.0, 0.5, -2.0), (2.0, 0.5, 0.0)]
    assert [c for c, _ in _parts(load_mesh(blender_files[0], prim_path="Crates"))] == [(0.0, 5.0, 0.0)]
    with pytest.raises(MeshError, match=r"no object or collection named 'Nope'; its surfaces: Cube, Cube\.001, Sphere"):
        load_mesh(blender_files[0], prim_path="Nope")
    BOX.export(tmp_path / "box.obj")
    with pytest.raises(MeshError, match=r"box\.obj: prim_path '/box' names a part of a USD, \.blend or \.fbx file"):
        load_mesh(tmp_path / "box.obj", prim_path="/box")


def test_an_fbx_file_loads_standing_up_in_metres(blender_files):
    parts = _parts(load_mesh(blender_files[1]))
    assert (2.0, 0.5, 0.0) in [c for c, _ in parts] and all(v > 0 for _, v in parts)


def test_a_draco_compressed_gltf_loads_through_blender(blender_files):
    # web and store assets often come Draco-compressed: trimesh reads every mesh of such a file
    # as one point (its vertices all zero, at their node's origin)
    assert trimesh.load(blender_files[2], force="mesh").area == 0.0
    parts = _parts(load_mesh(blender_files[2]))
    assert (2.0, 0.5, 0.0) in [c for c, _ in parts] and all(v > 0 for _, v in parts)


def test_an_unreadable_fbx_is_named_with_the_fix(tmp_path):
    bad = tmp_path / "broken.fbx"
    bad.write_bytes(b"not an fbx file at all")
    with pytest.raises(MeshError, match=r"broken\.fbx: Blender could not read it.*export the asset as USD"):
        load_mesh(bad)


def test_a_blender_child_that_hangs_is_stopped_with_a_message(tmp_path, monkeypatch):
    """A rig with a scripted driver makes Blender wait at exit forever: the read must end, name
    the file and say what to do."""
    import sys
    import time

    from mpmfx.geometry import mesh as mesh_module

    asset = tmp_path / "rig.blend"
    asset.write_bytes(b"BLENDER")
    monkeypatch.setattr(mesh_module, "bpy_available", lambda: True)
    monkeypatch.setattr(mesh_module, "child_command", lambda *a: [sys.executable, "-c", "import time; time.sleep(60)"])
    monkeypatch.setenv("MPMFX_BLENDER_TIMEOUT", "1")
    t0 = time.monotonic()
    with pytest.raises(MeshError, match=r"rig\.blend: Blender did not finish within 1 s.*driver"):
        load_mesh(asset)
    assert time.monotonic() - t0 < 20


def test_a_mesh_below_the_solvers_floor_is_refused_and_every_advised_shift_lands_inside():
    import re

    origin, size, floor = (-0.5, -0.5, -0.5), 1.0, -0.375  # 3 cells of grid 24 above the bottom
    rest = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    rest.apply_translation((0, floor + 0.1, 0))  # resting on the floor: fine
    check_in_domain(rest, origin=origin, size=size, name="box", floor=floor)
    sunk = rest.copy()
    sunk.apply_translation((0, -0.05, 0))  # in the domain, but below the floor's plane
    with pytest.raises(MeshError, match=r"box: starts below the solver's floor.*translate it by \(0, 0.05, 0\)"):
        check_in_domain(sunk, origin=origin, size=size, name="box", floor=floor)
    rng = np.random.default_rng(7)
    advised = 0
    for _ in range(300):
        box = trimesh.creation.box(extents=rng.uniform(0.01, 0.95, 3))
        box.apply_translation(rng.uniform(-0.9, 0.9, 3))
        try:
            check_in_domain(box, origin=origin, size=size, name="box", floor=floor)
            continue
        except MeshError as exc:
            found = re.search(r"translate it by \(([^)]*)\)", str(exc))
        if found is None:  # too big: the advice is to scale it
            continue
        box.apply_translation([float(x) for x in found.group(1).split(",")])
        check_in_domain(box, origin=origin, size=size, name="box", floor=floor)  # the advice works
        assert box.bounds[0][1] >= floor - 1e-6 * size
        advised += 1
    assert advised > 100
