"""Nothing stale, nothing misleading. Bad physics is said at run time, advice names
shot keys and helps, published outputs are the current variant's."""

from __future__ import annotations

from pathlib import Path

import pytest

import mpmfx
from mpmfx.cli import main
from tests.conftest import write_tiny_shot


def test_flags_cfl_above_the_cap_and_inverted_particles():
    from mpmfx.stages.qa import flags

    out = flags({1: {"mass": 1.0, "cfl_used": 0.4}, 2: {"mass": 1.0, "cfl_used": 1.6, "inverted": 12}})
    assert 1 not in out and "CFL 1.6" in "; ".join(out[2]) and "12 inverted" in "; ".join(out[2])


@pytest.fixture
def bad_physics(tmp_path, monkeypatch):
    """The tiny shot, with frame 3's QA made to show what a blown-up run shows."""
    import mpmfx.stages.simulate as sim

    real = sim._qa

    def qa(report, size):
        d = real(report, size)
        if d["substeps"]:  # not the initial state's zero-length advance
            sim_frame[0] += 1
            if sim_frame[0] == 3:
                d |= {"j_min": -0.06, "cfl_used": 1.6}
        return d

    sim_frame = [1]
    monkeypatch.setattr(sim, "_qa", qa)
    return write_tiny_shot(tmp_path, frame_end=4), tmp_path / "c"


def test_bad_physics_warns_at_run_time_and_strict_fails(bad_physics, capsys):
    shot, cache = bad_physics
    assert main(["run", str(shot), "--until", "simulate", "--cache", str(cache), "-q"]) == 0
    captured = capsys.readouterr()
    assert "frame 3" in captured.err and "inverted" in captured.err and "CFL 1.6" in captured.err
    assert "1 frame flagged" in captured.out  # the closing table says it too
    # cached now: the warning stands, and --strict turns it into a failure
    assert main(["run", str(shot), "--until", "simulate", "--cache", str(cache), "-q", "--strict"]) == 1
    assert "frame 3" in capsys.readouterr().err


def _advice(err: str) -> list[str]:
    """The `--set KEY=VALUE` suggestions in an error message."""
    import re

    return re.findall(r"--set (\S+=[^\s;,)]+)", err)


@pytest.mark.parametrize("setting", ["solver.dt_min=0.005", "solver.max_substeps_per_frame=3"])
def test_advice_names_shot_keys_and_following_it_helps(tmp_path, capsys, setting):
    shot = write_tiny_shot(tmp_path, frame_end=2)
    args = ["run", str(shot), "--until", "simulate", "--cache", str(tmp_path / "c"), "-q", "--set", setting]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "SolverConfig" not in err and "lower solver.cfl" not in err.lower()
    advice = _advice(err)
    assert advice and advice[0].split("=")[0] == setting.split("=")[0], err
    assert main([*args, "--set", advice[0]]) == 0, capsys.readouterr().err


def test_publishing_follows_every_run_and_the_label_names_the_overrides(tmp_path, monkeypatch):
    import json

    import mpmfx.stages.render as render_stage

    titles = []
    real = render_stage.FrameRenderer

    def spy(**kw):
        titles.append(kw.get("title", ""))
        return real(**kw)

    monkeypatch.setattr(render_stage, "FrameRenderer", spy)
    monkeypatch.chdir(tmp_path)
    shot = write_tiny_shot(tmp_path, frame_end=3)
    cache = tmp_path / "c"
    out = tmp_path / "renders" / "tiny"
    plain = mpmfx.load_shot(shot, cache_root=cache, quiet=True)
    plain.run()
    first = {p.name: p.read_bytes() for p in out.glob("[0-9]*.png")}
    variant = ["surface.radius_scale=1.3"]
    mpmfx.load_shot(shot, overrides=variant, cache_root=cache, quiet=True).run()
    beside = tmp_path / "renders" / "tiny@surface.radius_scale=1.3"
    assert json.loads((beside / "published.json").read_text())["overrides"] == variant
    assert json.loads((out / "published.json").read_text())["overrides"] == []  # the hand-off stays
    assert "surface.radius_scale=1.3" in titles[-1] and "radius_scale" not in titles[0]
    mpmfx.load_shot(shot, overrides=variant, cache_root=cache, quiet=True, publish_as="default").run()
    assert json.loads((out / "published.json").read_text())["overrides"] == variant  # asked for
    results = plain.run()  # all cached: the plain version is published again
    assert {r.state for r in results} == {"cached"}
    assert json.loads((out / "published.json").read_text())["overrides"] == []
    assert {p.name: p.read_bytes() for p in out.glob("[0-9]*.png")} == first


def test_usd_and_vdb_are_published_at_a_stable_path(tmp_path, monkeypatch, capsys):
    from pxr import Usd, UsdGeom, UsdVol

    monkeypatch.chdir(tmp_path)
    shot = write_tiny_shot(tmp_path, frame_end=3)
    args = ["run", str(shot), "--until", "export", "--cache", str(tmp_path / "c"), "-q"]
    stable = tmp_path / "published" / "tiny" / "shot.usda"
    assert main(args) == 0
    assert "published/tiny/shot.usda" in capsys.readouterr().out  # the closing table says where
    plain = mpmfx.load_shot(shot, cache_root=tmp_path / "c").entries()["export"].root.resolve()
    assert main([*args, "--set", "surface.radius_scale=1.5"]) == 0
    assert stable.parent.resolve() == plain  # a variant publishes beside the hand-off
    assert main([*args, "--set", "surface.radius_scale=1.5", "--publish-as", "default"]) == 0
    variant = mpmfx.load_shot(shot, overrides=["surface.radius_scale=1.5"], cache_root=tmp_path / "c")
    assert stable.parent.resolve() == variant.entries()["export"].root.resolve() != plain
    stage = Usd.Stage.Open(str(stable))  # a DCC opens the stable path: frames and VDBs resolve through it
    pts = UsdGeom.Mesh(stage.GetPrimAtPath("/World/surfaces/cube")).GetPointsAttr().Get(3)
    vol = UsdVol.Volume(stage.GetPrimAtPath("/World/volumes/cube_vdb"))
    asset = UsdVol.OpenVDBAsset(stage.GetPrimAtPath(vol.GetFieldPath("surface")))
    assert len(pts) > 0 and Path(asset.GetFilePathAttr().Get(3).resolvedPath).is_file()
    assert main(args) == 0  # the plain shot again: all cached, and published again
    assert stable.parent.resolve() == plain


def test_status_qa_has_units_whole_headers_and_the_first_frame(tmp_path, capsys):
    shot = write_tiny_shot(tmp_path, frame_end=3)
    args = [str(shot), "--cache", str(tmp_path / "c")]
    assert main(["run", *args, "--until", "simulate", "-q"]) == 0
    capsys.readouterr()
    assert main(["status", *args, "--qa"]) == 0
    out = capsys.readouterr().out
    assert "kinetic_energy" in out and "rejected_substeps" in out and "m/s" in out
    rows = [line.split()[0] for line in out.splitlines() if line.strip()[:1].isdigit()]
    assert rows == ["1", "2", "3"]


def test_version_and_no_warp_banner_on_stdout():
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "mpmfx.cli", "--version"], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == f"mpmfx {mpmfx.__version__}"
    code = (
        "import sys, mpmfx.bench as b, mpmfx.cli as c\n"
        "b.main = lambda *a, **k: (__import__('warp').init(), 0)[1]\n"
        "sys.exit(c.main(['bench', 'solver', '--quick']))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0 and "Warp" not in out.stdout


def test_a_run_on_a_machine_without_a_gpu_prints_no_cuda_warning(tmp_path):
    """A CPU machine is a supported one: no driver warning from Warp on any run (on a GPU machine
    Warp prints none either, so this holds on both)."""
    import subprocess
    import sys

    shot = write_tiny_shot(tmp_path, frame_end=2)
    cmd = [sys.executable, "-m", "mpmfx.cli", "run", str(shot), "--until", "surface", "-q"]
    out = subprocess.run([*cmd, "--cache", str(tmp_path / "c")], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "CUDA warning" not in out.stderr and "NVIDIA CUDA driver" not in out.stderr


def test_a_nan_mesh_vertex_is_bad_input_exit_2(tmp_path, capsys):
    shot = write_tiny_shot(tmp_path)
    lines = (tmp_path / "cube.obj").read_text().splitlines()
    first_v = next(i for i, line in enumerate(lines) if line.startswith("v "))
    lines[first_v] = "v nan 0.125 0.125"
    (tmp_path / "cube.obj").write_text("\n".join(lines) + "\n")
    assert main(["check", str(tmp_path / "cube.obj")]) == 2
    assert "NaN" in capsys.readouterr().err
    assert main(["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "c"), "-q"]) == 2
    assert "NaN" in capsys.readouterr().err
