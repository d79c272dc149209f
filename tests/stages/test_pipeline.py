"""The cache contract (docs/architecture.md, "The cache and its keys"), on a tiny shot, end to end on the CPU."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import mpmfx
from tests.conftest import write_tiny_shot

RAN = {"ran", "resumed"}


def _states(results):
    return {r.stage: r.state for r in results}


def _bytes(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.glob("*.npz"))}


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """One full run of the tiny shot; later tests build on its cache."""
    folder = tmp_path_factory.mktemp("shot")
    shot = write_tiny_shot(folder)
    cache = folder / "cache"
    cwd = os.getcwd()
    os.chdir(folder)  # renders/<shot>/ is published relative to the working directory
    try:
        results = mpmfx.load_shot(shot, cache_root=cache, quiet=True).run()
    finally:
        os.chdir(cwd)
    return shot, cache, results


def test_full_run_produces_every_output(first_run):
    shot, cache, results = first_run
    assert [r.stage for r in results] == ["voxelise", "simulate", "surface", "export", "render"]
    assert all(r.state == "ran" for r in results)
    sim, surf, exp, ren = (results[i].entry for i in range(1, 5))
    assert len(list((sim / "frames").glob("*.npz"))) == 6
    assert len(list((surf / "frames").glob("*.npz"))) == 6
    assert (exp / "shot.usda").is_file() and len(list((exp / "frames").glob("*.usdc"))) == 6
    assert len(list(exp.rglob("*.vdb"))) == 6
    assert len(list((ren / "frames").glob("*.png"))) == 6
    assert len(list((shot.parent / "renders" / "tiny").glob("[0-9]*.png"))) == 6
    assert (shot.parent / "renders" / "tiny" / "contact.png").is_file()


def test_second_run_is_all_cache_hits(first_run):
    shot, cache, _ = first_run
    results = mpmfx.load_shot(shot, cache_root=cache, quiet=True).run()
    assert set(_states(results).values()) == {"cached"}


def test_surface_change_reruns_only_surface_and_after(first_run):
    shot, cache, first = first_run
    sim_before = _bytes(first[1].entry / "frames")
    run = mpmfx.load_shot(shot, overrides=["surface.radius_scale=1.3"], cache_root=cache, quiet=True)
    states = _states(run.run(until="surface"))
    assert states == {"voxelise": "cached", "simulate": "cached", "surface": "ran"}
    assert {s.stage: s.state for s in run.status()}["export"] in {"stale", "missing"}
    assert _bytes(first[1].entry / "frames") == sim_before  # the simulation is untouched, byte for byte


def test_material_change_reruns_simulate_and_after(first_run):
    shot, cache, _ = first_run
    run = mpmfx.load_shot(shot, overrides=["objects.0.overrides.youngs_modulus=3000"], cache_root=cache, quiet=True)
    status = {s.stage: s for s in run.status()}
    assert status["voxelise"].state == "cached"
    assert status["simulate"].state == "stale" and "materials" in status["simulate"].why
    states = _states(run.run(until="surface"))
    assert states == {"voxelise": "cached", "simulate": "ran", "surface": "ran"}


KILLER = """
import sys, time
import mpmfx.stages.simulate as sim
_write = sim._write_frame
def slow(*a, **k):
    _write(*a, **k)
    time.sleep(0.4)   # give the test time to kill us between frames
sim._write_frame = slow
from mpmfx.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_killed_simulation_resumes_to_identical_frames(tmp_path):
    shot = write_tiny_shot(tmp_path, frame_end=12)
    ref_cache, cache = tmp_path / "ref", tmp_path / "killed"
    ref = mpmfx.load_shot(shot, cache_root=ref_cache, quiet=True).run(until="simulate")
    cmd = [sys.executable, "-c", KILLER, "run", str(shot), "--until", "simulate", "--cache", str(cache), "-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    run = mpmfx.load_shot(shot, cache_root=cache, quiet=True)
    frames_dir = run.entries()["simulate"].frames_dir
    deadline = time.time() + 300
    while time.time() < deadline and len(list(frames_dir.glob("[0-9]*.npz"))) < 6:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = len(list(frames_dir.glob("[0-9]*.npz")))
    assert 6 <= done < 12, "the run must have been killed part-way"
    assert not run.entries()["simulate"].complete()
    states = _states(run.run(until="simulate"))
    assert states["simulate"] == "resumed"
    assert _bytes(frames_dir) == _bytes(ref[1].entry / "frames")


def test_cli_status_and_clean(first_run, capsys):
    from mpmfx.cli import main

    shot, cache, _ = first_run
    assert main(["status", str(shot), "--cache", str(cache)]) == 0
    out = capsys.readouterr().out
    assert "voxelise" in out and "cached" in out
    assert main(["clean", str(shot), "--cache", str(cache), "--stage", "render"]) == 0
    assert main(["status", str(shot), "--cache", str(cache)]) == 0
    assert "render    missing" in capsys.readouterr().out.replace("  ", "  ")


def test_close_voids_is_a_surface_knob(first_run, tmp_path, capsys):
    """surface.close_voids reaches the surfacer (the closing changes the mesh, only surface
    re-runs); a negative radius is a config error naming the field. Three spacings: at one the
    gated closing finds nothing to fill on this lattice-like block (the mesh is the one without
    it since the redistancing starts from the crossing plane)."""
    from mpmfx.cli import main
    from mpmfx.io.frames import SurfaceFrame

    shot, cache, first = first_run
    h = mpmfx.load_shot(shot, cache_root=cache, quiet=True).shot.particle_spacing
    run = mpmfx.load_shot(shot, overrides=[f"surface.close_voids={3 * h}"], cache_root=cache, quiet=True)
    results = run.run(until="surface")
    assert _states(results) == {"voxelise": "cached", "simulate": "cached", "surface": "ran"}
    before = SurfaceFrame.read(first[2].entry / "frames" / "0003.npz").groups["Elastic"].vertices
    after = SurfaceFrame.read(results[2].entry / "frames" / "0003.npz").groups["Elastic"].vertices
    assert len(after) > 0 and (len(after) != len(before) or not np.array_equal(after, before))
    assert main(["run", str(shot), "--set", "surface.close_voids=-1", "--cache", str(tmp_path / "c")]) == 2
    assert "surface.close_voids" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()


def test_sharp_edges_is_a_surface_knob(first_run, tmp_path, capsys):
    """surface.sharp_edges (on by default) reaches the surfacer: turned off, the shot's block
    rounds its edges in the first frame (only surface re-runs); a value that is not a boolean is a
    config error naming the field."""
    from mpmfx.cli import main
    from mpmfx.io.frames import SurfaceFrame
    from mpmfx.shotfile import load_shot_config
    from mpmfx.stages.surface import surface_params

    shot, cache, first = first_run
    run = mpmfx.load_shot(shot, overrides=["surface.sharp_edges=false"], cache_root=cache, quiet=True)
    results = run.run(until="surface")
    assert _states(results) == {"voxelise": "cached", "simulate": "cached", "surface": "ran"}
    before = SurfaceFrame.read(first[2].entry / "frames" / "0001.npz").groups["Elastic"].vertices
    after = SurfaceFrame.read(results[2].entry / "frames" / "0001.npz").groups["Elastic"].vertices
    assert len(after) > 0 and (len(after) != len(before) or not np.array_equal(after, before))
    assert main(["run", str(shot), "--set", "surface.sharp_edges=maybe", "--cache", str(tmp_path / "c")]) == 2
    assert "surface.sharp_edges" in capsys.readouterr().err
    # without smoothing there is no edge gate to sharpen at: asked for, a config error, not a
    # silent no-op; left at its default, it goes off with the smoothing
    assert not surface_params(load_shot_config(shot, ["surface.smooth_iters=0"]), "Elastic").sharp_edges
    assert (
        main(
            [
                "run",
                str(shot),
                "--set",
                "surface.sharp_edges=true",
                "--set",
                "surface.smooth_iters=0",
                "--cache",
                str(tmp_path / "c"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "surface.sharp_edges" in err and "surface.smooth_iters" in err and str(shot.name) in err
    assert not (tmp_path / "c").exists()


def test_cli_bad_config_exit_2(tmp_path, capsys):
    from mpmfx.cli import main

    shot = write_tiny_shot(tmp_path, extra="\n[solver]\n")  # duplicate table: invalid TOML
    assert main(["run", str(shot), "--cache", str(tmp_path / "c")]) == 2
    assert "not valid TOML" in capsys.readouterr().err
    shot = write_tiny_shot(tmp_path)
    assert main(["run", str(shot), "--set", "solver.cfll=0.3", "--cache", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "solver.cfll" in err and "did you mean 'cfl'" in err
    assert not (tmp_path / "c").exists()  # nothing cached from a bad config


def test_exported_usd_matches_voxelised_plus_simulated(first_run):
    """World mapping at the export boundary: USD points = voxelised position + simulated displacement."""
    from pxr import Usd, UsdGeom

    from mpmfx.io.frames import read_arrays
    from mpmfx.io.usd import validate_stage

    _, _, results = first_run
    vox, sim, exp = results[0].entry, results[1].entry, results[3].entry
    stage = Usd.Stage.Open(str(exp / "shot.usda"))
    assert UsdGeom.GetStageUpAxis(stage) == "Y" and stage.GetTimeCodesPerSecond() == 24
    points = UsdGeom.Points(stage.GetPrimAtPath("/World/particles/cube_particles"))
    x0 = read_arrays(vox / "particles.npz")["x"]
    usd1 = np.asarray(points.GetPointsAttr().Get(1))
    assert np.allclose(usd1, x0, atol=1e-6)  # frame 1 is the voxelised state, in metres
    f6 = read_arrays(sim / "frames" / "0006.npz")
    usd6 = np.asarray(points.GetPointsAttr().Get(6))
    assert np.array_equal(usd6, f6["x"]) and not np.allclose(usd6, usd1)  # it moved, and export kept it exact
    assert validate_stage(exp / "shot.usda") == []


def test_exported_vdb_is_a_level_set(first_run):
    from mpmfx.io.vdb import read_vdb

    _, _, results = first_run
    vdbs = sorted(results[3].entry.rglob("*.vdb"))
    info = read_vdb(vdbs[0])
    grid = info["grids"]["surface"]
    assert grid["class"] == "level_set" and grid["active_voxel_count"] > 0
    assert info["metadata"]["shot"] == "tiny"


COLLIDER = """
[[colliders]]
name = "paddle"
shape = "box"
half_extents = [0.3, 0.04, 0.3]
friction = 0.0
keyframes = [{ time = 0.0, translate = [0.5, 0.2, 0.5] }, { time = 0.25, translate = [0.5, 0.28, 0.5] }]
"""


def test_moving_collider_holds_material_and_is_exported(tmp_path):
    """A keyframed box rising under the falling cube: no particle ends inside it; USD has its motion."""
    from pxr import Usd, UsdGeom

    shot = write_tiny_shot(tmp_path, extra=COLLIDER)
    results = mpmfx.load_shot(shot, cache_root=tmp_path / "c", quiet=True).run(until="export")
    from mpmfx.io.frames import read_arrays

    x = read_arrays(results[1].entry / "frames" / "0006.npz")["x"]
    dx = 1.0 / 24
    top = 0.2 + 0.08 * (5 / 24) / 0.25 + 0.04  # the paddle's top at frame 6 (t = 5/24 s)
    # without the paddle the cube would have fallen to ~0.13 m; with it, it rests on the paddle's top
    assert top - dx / 2 < x[:, 1].min() < top + 2 * dx
    stage = Usd.Stage.Open(str(results[3].entry / "shot.usda"))
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/World/colliders/paddle"))
    y1 = xf.ComputeLocalToWorldTransform(1).ExtractTranslation()[1]
    y6 = xf.ComputeLocalToWorldTransform(6).ExtractTranslation()[1]
    assert y1 == pytest.approx(0.2) and y6 == pytest.approx(0.2 + 0.08 * (5 / 24) / 0.25)


def test_mesh_outside_domain_fails_clearly_and_caches_nothing(tmp_path, capsys):
    from mpmfx.cli import main

    shot = write_tiny_shot(tmp_path)
    code = main(["run", str(shot), "--set", "objects.0.translate=[3.0, 0.4, 0.5]", "--cache", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert code == 2  # bad input (the README's exit codes)
    assert "objects.cube" in err and "cube.obj" in err and "domain" in err
    assert not list((tmp_path / "c").rglob("voxelise-*"))  # no half-made entry


def test_an_object_starting_below_the_solvers_floor_is_bad_input_naming_it(tmp_path, capsys):
    from mpmfx.cli import main

    shot = write_tiny_shot(tmp_path)  # grid 24 from y = 0: the floor is 3 cells up, y = 0.125
    code = main(["run", str(shot), "--set", "objects.0.translate=[0.5, 0.2, 0.5]", "--cache", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert code == 2
    assert "objects.cube" in err and "below the solver's floor" in err and "translate it by (0, 0.05, 0)" in err
    assert not list((tmp_path / "c").rglob("voxelise-*"))


def test_a_thickness_warning_reaches_the_closing_table_cached_or_not(tmp_path, capsys):
    from mpmfx.cli import main

    shot = write_tiny_shot(tmp_path)
    args = ["run", str(shot), "--set", "objects.0.scale=0.7", "--until", "voxelise"]
    for state in ("ran", "cached"):  # the cube at 4.2 cells across: a warning
        assert main([*args, "--cache", str(tmp_path / "c")]) == 0
        out = capsys.readouterr().out
        table, _, below = out.partition("voxelise  " + state)
        assert "warnings:" in below and "objects.cube: thinnest feature 4." in below, out


def _cuda_available() -> bool:
    import warp as wp

    wp.config.quiet = True
    return wp.is_cuda_available()


@pytest.mark.skipif(_cuda_available(), reason="this machine has CUDA: the message is for machines without it")
def test_device_cuda_without_gpu_says_what_to_do(tmp_path, capsys):
    from mpmfx.cli import main

    shot = write_tiny_shot(tmp_path)
    assert main(["run", str(shot), "--device", "cuda", "-q", "--cache", str(tmp_path / "c")]) == 1
    assert "--device cpu" in capsys.readouterr().err
    assert not list((tmp_path / "c").rglob("simulate-*"))


def test_particle_debug_render_reuses_the_simulation(first_run, tmp_path, monkeypatch):
    """The particle debug look: switching render.mode re-runs only render."""
    shot, cache, _ = first_run
    monkeypatch.chdir(tmp_path)
    results = mpmfx.load_shot(shot, overrides=["render.mode=particles"], cache_root=cache, quiet=True).run()
    assert _states(results) == {
        "voxelise": "cached",
        "simulate": "cached",
        "surface": "cached",
        "export": "cached",
        "render": "ran",
    }
    pngs = sorted((tmp_path / "renders" / "tiny@render.mode=particles").glob("[0-9]*.png"))
    assert len(pngs) == 6 and all(p.stat().st_size > 1000 for p in pngs)


@pytest.fixture(scope="module")
def density_run(first_run):
    """The tiny shot again with surface.density on, up to export, on first_run's cache."""
    shot, cache, first = first_run
    run = mpmfx.load_shot(shot, overrides=["surface.density=true"], cache_root=cache, quiet=True)
    return mpmfx.load_shot(shot, cache_root=cache, quiet=True), run, run.run(until="export")


def test_density_flag_changes_the_surface_key_and_reruns_from_surface(density_run):
    off, on, results = density_run
    assert _states(results) == {"voxelise": "cached", "simulate": "cached", "surface": "ran", "export": "ran"}
    before, after = off.entries(), on.entries()
    assert after["simulate"].key == before["simulate"].key
    assert after["surface"].key != before["surface"].key


def test_density_grid_is_a_fog_volume_in_the_vdb_and_the_usd(density_run):
    from pxr import Usd, UsdVol

    from mpmfx.io.frames import read_arrays
    from mpmfx.io.usd import validate_stage
    from mpmfx.io.vdb import read_vdb

    *_, results = density_run
    exp = results[3].entry
    vdb = exp / "vdb" / "Elastic" / "0003.vdb"
    grids = read_vdb(vdb, with_values=True)["grids"]
    fog, surface = grids["density"], grids["surface"]
    assert fog["class"] == "fog_volume" and fog["background"] == 0.0
    assert fog["voxel_size"] == surface["voxel_size"] and fog["active_voxel_count"] > 0
    stored = read_arrays(results[2].entry / "frames" / "0003.npz")
    leaves = len(stored["Elastic.density_blocks"]) + len(stored["Elastic.inside_ijk"])
    assert fog["active_voxel_count"] <= leaves * 512  # only the stored leaves and inside tiles
    assert fog["values"].min() >= 0.0 and fog["values"].max() == pytest.approx(1.0, abs=1e-3)
    assert 0.05 < fog["values"][(fog["values"] > 0) & (fog["values"] < 1)].mean() < 0.95  # a soft edge
    stage = Usd.Stage.Open(str(exp / "shot.usda"))
    volume = UsdVol.Volume(stage.GetPrimAtPath("/World/volumes/cube_vdb"))
    asset = UsdVol.OpenVDBAsset(stage.GetPrimAtPath(volume.GetFieldPath("density")))
    assert asset.GetFieldNameAttr().Get() == "density" and asset.GetFieldClassAttr().Get() == "fogVolume"
    assert Path(asset.GetFilePathAttr().Get(3).resolvedPath).resolve() == vdb.resolve()
    assert validate_stage(exp / "shot.usda") == []


def test_density_off_writes_no_density(first_run):
    from pxr import Usd, UsdVol

    from mpmfx.io.frames import read_arrays
    from mpmfx.io.vdb import read_vdb

    _, _, results = first_run
    surf, exp = results[2].entry, results[3].entry
    assert not [k for k in read_arrays(surf / "frames" / "0003.npz") if "density" in k]
    assert set(read_vdb(exp / "vdb" / "Elastic" / "0003.vdb")["grids"]) == {"surface", "vel"}
    stage = Usd.Stage.Open(str(exp / "shot.usda"))
    assert set(UsdVol.Volume(stage.GetPrimAtPath("/World/volumes/cube_vdb")).GetFieldPaths()) == {"surface", "vel"}


def test_a_surface_too_big_for_one_call_names_the_shot_key_and_keeps_the_cache(first_run, monkeypatch, capsys):
    """The surfacer's "too many blocks" error reaches the user as the shot file, the key to
    change and the frame, with exit code 1; the cached stages stay as they were."""
    from mpmfx.cli import main

    shot, cache, first = first_run
    sim_before = _bytes(first[1].entry / "frames")
    monkeypatch.setattr("mpmfx.surface.sparse.MAX_ACTIVE_BLOCKS", 1)
    rc = main(
        [
            "run",
            str(shot),
            "--cache",
            str(cache),
            "--until",
            "surface",
            "--set",
            "surface.radius_scale=1.45",
            "--workers",
            "1",
            "-q",
        ]
    )
    err = capsys.readouterr().err
    assert rc == 1
    assert f"error: {shot}: surface.voxel_size, frame 1, group" in err
    assert "raise voxel_size" in err and "--set surface.voxel_size=" in err
    assert _bytes(first[1].entry / "frames") == sim_before
    run = mpmfx.load_shot(shot, overrides=["surface.radius_scale=1.45"], cache_root=cache, quiet=True)
    assert not run.entries()["surface"].root.exists()  # no half-made entry left


def test_without_vdb_export_the_surface_keeps_the_mesh_and_drops_the_leaves(first_run):
    """The level set's leaves have one reader, the VDB export: a shot that writes no VDB stores
    only the meshes (same mesh, a fraction of the bytes), and its USD still plays them."""
    from mpmfx.io.frames import SurfaceFrame

    shot, cache, first = first_run
    run = mpmfx.load_shot(shot, overrides=["export.vdb=false"], cache_root=cache, quiet=True)
    results = run.run(until="export")
    assert _states(results) == {"voxelise": "cached", "simulate": "cached", "surface": "ran", "export": "ran"}
    with_leaves = first[2].entry / "frames" / "0003.npz"
    without = results[2].entry / "frames" / "0003.npz"
    a, b = SurfaceFrame.read(with_leaves).groups["Elastic"], SurfaceFrame.read(without).groups["Elastic"]
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)
    assert a.blocks is not None and b.blocks is None and b.vel_blocks is None
    assert without.stat().st_size < 0.6 * with_leaves.stat().st_size
    assert not list(results[3].entry.rglob("*.vdb")) and len(list((results[3].entry / "frames").glob("*.usdc"))) == 6
