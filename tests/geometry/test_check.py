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


def _shot_with_plate(folder, plate_y: float):
    """A shot (grid 24 on a 1 m domain from y = 0: the floor is y = 0.125) with a 30 x 30 x 4 cm
    plate modelled in centimetres (scale 0.01), a cube, and a pool of water."""
    from tests.conftest import write_tiny_shot

    trimesh.creation.box(extents=(30, 4, 30)).export(folder / "plate_cm.obj")
    shot = write_tiny_shot(folder)
    shot.write_text(
        shot.read_text()
        + f"""
[[objects]]
name = "plate"
mesh = "plate_cm.obj"
material = "Soft"
scale = 0.01
translate = [0.5, {plate_y}, 0.5]

[[objects]]
name = "pool"
mesh = "cube.obj"
material = "Water"
translate = [0.5, 0.7, 0.5]
"""
    )
    return shot


def test_check_a_shot_checks_each_object_where_and_at_the_grid_the_shot_puts_it(tmp_path, capsys, monkeypatch):
    from mpmfx.cli import main

    monkeypatch.chdir(tmp_path)
    shot = _shot_with_plate(tmp_path, plate_y=0.2)
    assert main(["check", str(shot)]) == 1  # the plate is 4 cm: ~1 cell at grid 24
    out = capsys.readouterr().out
    assert "objects.plate" in out and "objects.cube" in out and "pool" in out
    report = json.loads((tmp_path / "renders" / "check" / "tiny" / "report.json").read_text())
    plate, cube = report["objects"]["plate"], report["objects"]["cube"]
    assert plate["grid_n"] == cube["grid_n"] == 24 and plate["dx"] == pytest.approx(1 / 24)
    assert plate["verdict"] == "fail" and cube["verdict"] == "pass"
    assert plate["regions"][0]["thickness_cells"] == pytest.approx(0.04 * 24, abs=0.3)  # metres, not cm
    assert plate["regions"][0]["bbox_min"][1] == pytest.approx(0.18, abs=0.01)  # where the shot places it
    assert "skipped" in report["objects"]["pool"]
    assert (tmp_path / "renders" / "check" / "tiny" / "thickness_plate.png").is_file()
    # another grid on the command line, the shot's domain kept
    assert main(["check", str(shot), "--grid-n", "30", "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["objects"]["plate"]["dx"] == pytest.approx(1 / 30)


def test_check_a_shot_refuses_an_object_below_the_floor_and_writes_nothing(tmp_path, capsys, monkeypatch):
    from mpmfx.cli import main

    monkeypatch.chdir(tmp_path)
    shot = _shot_with_plate(tmp_path, plate_y=0.1)  # its bottom at y = 0.08, below the floor's plane
    assert main(["check", str(shot)]) == 2
    err = capsys.readouterr().err
    assert "objects.plate" in err and "below the solver's floor" in err and "translate it by (0, 0.045, 0)" in err
    assert not (tmp_path / "renders").exists()
    assert main(["check", str(shot), "--domain=0,0,0,1"]) == 2
