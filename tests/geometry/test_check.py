import json

import pytest
import trimesh

from mpmfx.check import run_check

from .conftest import slab, sphere_with_fin


def test_check_writes_report_and_heatmap(tmp_path, capsys):
    path = tmp_path / "fin.obj"
    sphere_with_fin(0.05).export(path)
    code = run_check(str(path), grid_n=24, out_dir=tmp_path / "out")
    assert code == 1  # fin is ~1.1 cells at grid 24 with the padded default domain
    out = capsys.readouterr().out
    assert "FAIL" in out
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["verdict"] == "fail" and report["grid_n"] == 24
    assert report["domain"]["size"] == pytest.approx(0.65 * 1.1)
    png = tmp_path / "out" / "thickness.png"
    import imageio.v3 as iio

    img = iio.imread(png)
    assert img.shape[0] > 100 and img.std() > 5  # not a blank frame
    red = (img[..., 0] > 150) & (img[..., 1] < 100)
    assert red.sum() > 50  # the fin shows red


def test_check_json_and_pass(tmp_path, capsys):
    path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=3, radius=0.5).export(path)
    code = run_check(str(path), grid_n=16, as_json=True, out_dir=tmp_path / "o")
    assert code == 0
    assert json.loads(capsys.readouterr().out)["verdict"] == "pass"


def test_check_explicit_domain(tmp_path, capsys):
    path = tmp_path / "slab.ply"
    slab(0.1).export(path)
    assert (
        run_check(str(path), grid_n=40, origin=(-0.5, -0.5, -0.5), size=1.0, out_dir=tmp_path / "o") == 0
    )  # 4 cells: WARN exits 0
    assert "WARN" in capsys.readouterr().out


def test_check_bad_input_exits_2(tmp_path, capsys):
    assert run_check(str(tmp_path / "nope.obj"), grid_n=32, out_dir=tmp_path) == 2
    assert "nope.obj" in capsys.readouterr().err
    assert run_check(str(tmp_path / "nope.obj"), grid_n=0, out_dir=tmp_path) == 2


def test_check_says_open_and_non_manifold_in_the_table_and_the_json(tmp_path, capsys):
    import json

    import trimesh

    from mpmfx.check import run_check

    box = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2], process=False)  # one side missing
    open_box.export(tmp_path / "open.obj")
    box.export(tmp_path / "closed.obj")
    assert run_check(str(tmp_path / "open.obj"), grid_n=8, out_dir=tmp_path / "o") in (0, 1)
    assert "open" in capsys.readouterr().out
    run_check(str(tmp_path / "open.obj"), grid_n=8, out_dir=tmp_path / "o", as_json=True)
    data = json.loads(capsys.readouterr().out)
    assert data["mesh"]["watertight"] is False and data["mesh"]["open_edges"] > 0
    run_check(str(tmp_path / "closed.obj"), grid_n=8, out_dir=tmp_path / "c", as_json=True)
    data = json.loads(capsys.readouterr().out)
    assert data["mesh"] == {"watertight": True, "open_edges": 0, "non_manifold_edges": 0}


def test_check_prim_path_checks_one_part_of_a_usd_file(tmp_path, capsys, monkeypatch):
    # a set with a thick block and a thin plate: each part alone gets its own verdict
    from pxr import Gf, Usd, UsdGeom

    from mpmfx.cli import main

    monkeypatch.chdir(tmp_path)  # the report and heatmap go to ./renders/check/

    path = tmp_path / "set.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    for name, part, x in (("block", trimesh.creation.box(extents=(0.5, 0.5, 0.5)), 0.0), ("plate", slab(0.02), 1.0)):
        geom = UsdGeom.Mesh.Define(stage, f"/set/{name}")
        geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        geom.CreatePointsAttr([Gf.Vec3f(*(p + (x, 0, 0))) for p in part.vertices])
        geom.CreateFaceVertexCountsAttr([3] * len(part.faces))
        geom.CreateFaceVertexIndicesAttr([int(i) for i in part.faces.ravel()])
    stage.GetRootLayer().Save()
    verdicts = {}
    for prim in ("/set/block", "/set/plate"):
        code = main(["check", str(path), "--prim-path", prim, "--grid-n", "32", "--json"])
        verdicts[prim] = (code, json.loads(capsys.readouterr().out)["verdict"])
    assert verdicts == {"/set/block": (0, "pass"), "/set/plate": (1, "fail")}
    assert main(["check", str(path), "--prim-path", "/nope"]) == 2
    assert "'/nope' not found" in capsys.readouterr().err
