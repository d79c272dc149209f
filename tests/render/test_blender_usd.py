"""A real client: Blender (bpy, its own USD libraries, in its own process) opens the exported
USD stage of a small shot, and sees what the pipeline wrote; the Cycles render stage draws it."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mpmfx
from mpmfx.blender import bpy_available
from mpmfx.io.frames import SurfaceFrame
from mpmfx.publish import publish_name
from tests.conftest import write_tiny_shot

# Two objects (two surface groups), a keyframed collider: every kind of prim the export writes.
EXTRA = """
[[objects]]
name = "pool"
mesh = "cube.obj"
material = "Water"
translate = [0.25, 0.25, 0.5]
scale = 0.6

[[colliders]]
name = "paddle"
shape = "box"
half_extents = [0.05, 0.05, 0.05]
keyframes = [{ time = 0.0, translate = [0.2, 0.5, 0.2] }, { time = 0.2, translate = [0.3, 0.5, 0.2] }]
"""

# Runs inside Blender: import the stage as the render stage does, report what came in.
INSPECT = """
import json, sys
import bpy
from mpmfx.render.cycles_job import import_stage
bpy.ops.wm.read_factory_settings(use_empty=True)
got = import_stage(sys.argv[1])
scene = bpy.context.scene
out = {"frame_range": [scene.frame_start, scene.frame_end], "fps": scene.render.fps / scene.render.fps_base,
       "names": {k: sorted(n for n, _ in v) for k, v in got.items()}, "frames": {}}
for f in json.loads(sys.argv[2]):
    scene.frame_set(f)
    dg = bpy.context.evaluated_depsgraph_get()
    row = {}
    for kind in ("meshes", "points"):
        for name, obj in got[kind]:
            data = obj.evaluated_get(dg).data
            vel = data.attributes.get("velocity")
            speeds = [0.0] if vel is None else [v.vector.length for v in vel.data]
            row[f"{kind}/{name}"] = {"count": len(data.vertices if kind == "meshes" else data.points),
                                     "has_velocity": vel is not None, "max_speed": max(speeds, default=0.0)}
    for name, obj in got["volumes"]:
        grids = obj.data.grids
        row[f"volumes/{name}"] = {"loaded": grids.load(), "file": bpy.path.abspath(grids.frame_filepath),
                                  "grids": sorted(g.name for g in grids)}
    out["frames"][f] = row
print("INSPECT " + json.dumps(out))
"""

pytestmark = pytest.mark.skipif(
    not bpy_available(), reason="bpy (Blender as a module) is part of the test set-up: bash setup.sh test installs it"
)


def _blender(script: str, *args: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(Path(mpmfx.__file__).parents[1])}
    res = subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return res.stdout


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("blender")
    shot = write_tiny_shot(folder, frame_end=4, extra=EXTRA)
    run = mpmfx.load_shot(shot, cache_root=folder / "cache", quiet=True)
    results = {r.stage: r.entry for r in run.run(until="export")}
    return folder, shot, results


def test_blender_sees_every_object_frame_and_volume(exported):
    _, _, entries = exported
    frames = [2, 4]
    line = next(
        s
        for s in _blender(INSPECT, str(entries["export"] / "shot.usda"), json.dumps(frames)).splitlines()
        if s.startswith("INSPECT ")
    )
    seen = json.loads(line.removeprefix("INSPECT "))
    assert seen["frame_range"] == [1, 4] and seen["fps"] == pytest.approx(24.0)
    # a surface per group (one per material), named after its object; particles per object,
    # the level sets, the collider, the shot camera
    assert seen["names"]["meshes"] == ["cube", "pool"]
    assert seen["names"]["points"] == ["cube_particles", "pool_particles"]
    assert seen["names"]["volumes"] == ["cube_vdb", "pool_vdb"]
    assert seen["names"]["colliders"] == ["paddle"]
    assert seen["names"]["cameras"] == ["camera"]
    named = {"Elastic": "cube", "Water": "pool"}
    for f in frames:
        row = seen["frames"][str(f)]
        surf = SurfaceFrame.read(entries["surface"] / "frames" / f"{f:04d}.npz").groups
        for g, data in surf.items():
            mesh = row[f"meshes/{named[g]}"]
            assert mesh["count"] == len(data.vertices) > 0, (f, g)
            assert mesh["has_velocity"] and mesh["max_speed"] > 0.0, (f, g)
            vol = row[f"volumes/{named[g]}_vdb"]
            assert vol["loaded"] and "surface" in vol["grids"] and "vel" in vol["grids"]
            assert Path(vol["file"]) == (entries["export"] / "vdb" / g / f"{f:04d}.vdb").resolve()
        assert row["points/cube_particles"]["count"] > 0 and row["points/cube_particles"]["has_velocity"]


CYCLES = [
    "render.engine=cycles",
    "render.samples=2",
    "render.width=96",
    "render.height=64",
    "render.frame_step=2",
    "render.movie=true",
    "render.basin=0.05",
    'render.looks={basin = "glass", paddle = "glass"}',
]


@pytest.fixture(scope="module")
def cycles(exported):
    """The render stage in Cycles on the exported shot (a variant: it publishes beside it)."""
    folder, shot, _ = exported
    cwd = os.getcwd()
    os.chdir(folder)  # renders/<shot>/ is published relative to the working directory
    try:
        run = mpmfx.load_shot(shot, cache_root=folder / "cache", quiet=True, overrides=CYCLES)
        entries = {r.stage: r.entry for r in run.run()}
    finally:
        os.chdir(cwd)
    return folder, run, entries


def test_cycles_render_stage_draws_the_looks(cycles):
    """The render stage in Cycles: every frame written (frame_step holds the ones between), the
    .blend saved, the jelly drawn red and in frame, through the glass of a tank (render.looks.basin)."""
    import imageio.v2 as imageio

    folder, run, entries = cycles
    entry = entries["render"]
    published = folder / "renders" / publish_name(run.shot)
    assert published.name.startswith("tiny@render.engine=cycles,")
    # (failed once in four full runs with no PNG published; say what was there, should it recur)
    seen = {
        "published": sorted(p.name for p in published.iterdir()) if published.exists() else None,
        "render entry": sorted(p.name for p in (entry / "frames").glob("*")) if (entry / "frames").exists() else None,
        "renders/": sorted(p.name for p in (folder / "renders").glob("*")) if (folder / "renders").exists() else None,
    }
    assert sorted(p.name for p in published.glob("[0-9]*.png")) == [f"{f:04d}.png" for f in range(1, 5)], seen
    assert (published / "tiny.blend").stat().st_size > 0 and (published / "tiny.mp4").is_file()
    assert not (folder / "renders" / "tiny").exists()  # a variant never replaces the hand-off
    one, two = (imageio.imread(entry / "frames" / f"{f:04d}.png") for f in (1, 2))
    assert np.array_equal(one, two)  # frame 2 holds frame 1 (frame_step = 2)
    job_file = sorted(entry.glob("cycles*_job.json"))[0]
    job = json.loads(job_file.read_text())  # one Blender job, or the first chunk's on Dask workers
    assert job["looks"]["basin"] == "glass" and job["collider_looks"] == {"paddle": "glass"}
    # the render looks through the camera the USD carries
    assert job["camera"] == json.loads((entries["export"] / "manifest.json").read_text())["camera"]
    rgb = imageio.imread(entry / "frames" / "0003.png")[..., :3].astype(int)
    jelly = (rgb[..., 0] > rgb[..., 1] + 40) & (rgb[..., 0] > rgb[..., 2] + 30)
    assert 0.01 < jelly.mean() < 0.6, "the jelly cube should be in the picture, red, and not fill it"


# Runs inside Blender: open the hand-off .blend where it was published, count vertices per frame.
PLAY = """
import json, sys
import bpy
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
scene = bpy.context.scene
out = {"paths": [c.filepath for c in bpy.data.cache_files], "counts": {}}
for f in json.loads(sys.argv[2]):
    scene.frame_set(f)
    dg = bpy.context.evaluated_depsgraph_get()
    out["counts"][f] = {o.name: len(o.evaluated_get(dg).data.vertices) for o in bpy.data.objects if o.type == "MESH"}
print("PLAY " + json.dumps(out))
"""


def test_the_published_blend_plays_the_published_usd(cycles, tmp_path):
    """renders/<name>/<shot>.blend, opened from there, animates: its meshes have each frame's
    vertex count; and it still does with the project folder moved."""
    folder, run, entries = cycles
    name = publish_name(run.shot)
    moved = tmp_path / "project"
    moved.mkdir()
    for part in ("renders", "published", "cache"):
        shutil.copytree(folder / part, moved / part, symlinks=True)
    blend = moved / "renders" / name / "tiny.blend"
    line = next(s for s in _blender(PLAY, str(blend), "[1, 4]").splitlines() if s.startswith("PLAY "))
    got = json.loads(line.removeprefix("PLAY "))
    assert got["paths"] == [f"//../../published/{name}/shot.usda"]
    for f in (1, 4):
        surf = SurfaceFrame.read(entries["surface"] / "frames" / f"{f:04d}.npz").groups
        assert got["counts"][str(f)]["cube"] == len(surf["Elastic"].vertices) > 0, f
        assert got["counts"][str(f)]["pool"] == len(surf["Water"].vertices) > 0, f
    assert got["counts"]["1"]["cube"] != got["counts"]["4"]["cube"]  # it moves: not frozen at frame 1


def test_a_gpu_render_on_a_machine_without_one_says_so_and_renders_on_the_cpu(exported, capsys):
    """render.device = gpu where Blender finds no OptiX / CUDA / HIP / oneAPI / Metal device (as
    here and in CI): one line says so, and Cycles draws the frame on the CPU."""
    folder, shot, _ = exported
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        run = mpmfx.load_shot(
            shot,
            cache_root=folder / "cache",
            quiet=True,
            overrides=["render.engine=cycles", "render.device=gpu", "render.samples=1", "render.width=64"]
            + ["render.height=48", "render.movie=false"],
        )
        entry = {r.stage: r for r in run.run(frames=[1])}["render"].entry
    finally:
        os.chdir(cwd)
    err = capsys.readouterr().err
    assert "render.device = gpu" in err and "renders on the CPU" in err, err[-2000:]
    assert (entry / "frames" / "0001.png").stat().st_size > 0


def test_material_lands_on_the_drawn_ground(exported):
    """The renders' ground is the solver's floor (its plane), where material stops."""
    from mpmfx.io.frames import ParticleFrame
    from mpmfx.render.camera import solver_floor
    from mpmfx.shotfile import load_shot_config

    _, shot_path, entries = exported
    shot = load_shot_config(shot_path)
    floor, dx = solver_floor(shot), shot.domain.size / shot.domain.grid_n
    assert floor == pytest.approx(shot.domain.origin[1] + 3 * dx)
    lowest = [ParticleFrame.read(p).x[:, 1].min() for p in sorted((entries["simulate"] / "frames").glob("*.npz"))]
    assert min(lowest) > floor - 0.5 * dx  # an impact presses in less than half a cell, never through
    assert lowest[-1] < floor + dx  # and the pool has landed on it by the last frame


def test_preview_engine_and_engine_switch_rerender_only(exported, tmp_path, monkeypatch):
    """render.engine = preview (PyVista) renders the same frames; switching engines re-runs only render."""
    _, shot, _ = exported
    monkeypatch.chdir(tmp_path)
    cache = exported[0] / "cache"
    results = mpmfx.load_shot(shot, cache_root=cache, quiet=True, overrides=["render.engine=preview"]).run()
    assert {r.stage: r.state for r in results} == {
        "voxelise": "cached",
        "simulate": "cached",
        "surface": "cached",
        "export": "cached",
        "render": "ran",
    }
    pngs = sorted((tmp_path / "renders" / "tiny@render.engine=preview").glob("[0-9]*.png"))
    assert len(pngs) == 4 and all(p.stat().st_size > 1000 for p in pngs)


@pytest.fixture(scope="module")
def three_of_four(exported, tmp_path_factory):
    """The same shot exported for frames 1-3 of its 1-4 (`--frames 1:3`), in a cache of its own."""
    folder, shot, _ = exported
    cache = tmp_path_factory.mktemp("three") / "cache"
    run = mpmfx.load_shot(shot, cache_root=cache, quiet=True)
    return run, {r.stage: r.entry for r in run.run(until="export", frames=[1, 2, 3])}


def test_the_usd_is_ready_for_a_dcc(three_of_four):
    """pxr reads the hand-off as a DCC would: surfaces visible and named after their objects, each
    bound to a UsdPreviewSurface of its look with a displayColor; particles and level sets
    hidden; the render camera; the frame range that was run."""
    from pxr import Gf, Usd, UsdGeom, UsdShade

    from mpmfx.render.camera import render_camera
    from mpmfx.render.looks import preview_surface

    run, entries = three_of_four
    stage = Usd.Stage.Open(str(entries["export"] / "shot.usda"))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1, 3)
    for name, look in (("cube", "jelly"), ("pool", "water")):
        prim = stage.GetPrimAtPath(f"/World/surfaces/{name}")
        assert prim.IsA(UsdGeom.Mesh) and UsdGeom.Imageable(prim).ComputeVisibility(2) == UsdGeom.Tokens.inherited
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        assert material.GetPrim().GetName() == look
        shader = material.ComputeSurfaceSource()[0]
        assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
        want = preview_surface(look)
        assert shader.GetInput("diffuseColor").Get() == Gf.Vec3f(*want["colour"])
        assert shader.GetInput("opacity").Get() == pytest.approx(want["opacity"])
        assert shader.GetInput("ior").Get() == pytest.approx(want["ior"])
        colour = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor").Get()
        assert tuple(colour[0]) == pytest.approx(want["colour"])
    assert preview_surface("water")["opacity"] < 0.5 and preview_surface("jelly")["opacity"] == 1.0
    for path in ("/World/particles/cube_particles", "/World/particles/pool_particles", "/World/volumes/cube_vdb"):
        assert UsdGeom.Imageable(stage.GetPrimAtPath(path)).ComputeVisibility(2) == UsdGeom.Tokens.invisible
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/camera"))
    want = json.loads((entries["export"] / "manifest.json").read_text())["camera"]
    assert want == json.loads(
        json.dumps(render_camera(run.shot))
    )  # the preview engine's 3/4 view: what the frames show
    xf = cam.ComputeLocalToWorldTransform(1)
    assert tuple(xf.ExtractTranslation()) == pytest.approx(want["position"])
    assert cam.GetFocalLengthAttr().Get() == pytest.approx(want["focal_length"] / 100)
    assert cam.GetHorizontalApertureAttr().Get() == pytest.approx(want["horizontal_aperture"] / 100)
    assert cam.GetVerticalApertureAttr().Get() == pytest.approx(want["vertical_aperture"] / 100)


# Runs inside Blender: a plain import (the importer's defaults), then one with hidden prims too.
PLAIN = """
import json, sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=sys.argv[1])
scene = bpy.context.scene
out = {"range": [scene.frame_start, scene.frame_end],
       "objects": {o.name: [o.type, [m.name for m in o.data.materials] if o.type == "MESH" else []]
                   for o in bpy.data.objects if o.type in ("MESH", "POINTCLOUD", "VOLUME", "CAMERA")}}
cam = next(o for o in bpy.data.objects if o.type == "CAMERA")
out["lens"] = [cam.data.lens, cam.data.sensor_width]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=sys.argv[1], import_visible_only=False)
out["hidden"] = {o.name: o.hide_render for o in bpy.data.objects if o.type == "POINTCLOUD"}
print("PLAIN " + json.dumps(out))
"""


def test_a_plain_blender_import_gets_named_surfaces_with_materials_and_no_particles(three_of_four):
    _, entries = three_of_four
    line = next(s for s in _blender(PLAIN, str(entries["export"] / "shot.usda")).splitlines() if s.startswith("PLAIN "))
    got = json.loads(line.removeprefix("PLAIN "))
    assert got["range"] == [1, 3]
    objects = got["objects"]
    assert objects["cube"] == ["MESH", ["jelly"]] and objects["pool"] == ["MESH", ["water"]]
    assert objects["paddle"][0] == "MESH" and objects["camera"][0] == "CAMERA"
    assert not [n for n, (kind, _) in objects.items() if kind == "POINTCLOUD"]  # hidden: not imported
    assert not [n for n in objects if "." in n]  # no mesh.001: every name is its own
    assert got["lens"] == pytest.approx([35.0, 36.0])
    assert sorted(got["hidden"]) == ["cube_particles", "pool_particles"]  # there as data, when asked for


# Runs inside Blender: build the lit scene as the render stage's child does, then report the
# world's environment, where near-horizontal rays from the camera meet the ground, and the
# extent of every surface mesh as drawn (clipped) and as imported (its clip modifier off).
SCENE = """
import json, math, sys
import bpy
from mathutils import Vector
from mpmfx.render import cycles_job
from mpmfx.render.blender_scene import Y_UP_TO_Z_UP
job = json.loads(open(sys.argv[1]).read())
cycles_job.build_scene(job)
scene = bpy.context.scene
out = {"env": [n.image.filepath for n in scene.world.node_tree.nodes if n.type == "TEX_ENVIRONMENT"]}
ground = bpy.data.objects["ground"]
eye = scene.camera.matrix_world.translation
dip = math.tan(math.radians(float(sys.argv[2])))
dg = bpy.context.evaluated_depsgraph_get()
out["horizon"] = []
for k in range(16):
    a = 2 * math.pi * k / 16
    d = Vector((math.cos(a), math.sin(a), -dip)).normalized()
    hit = ground.ray_cast(ground.matrix_world.inverted() @ eye, ground.matrix_world.inverted().to_3x3() @ d, depsgraph=dg)
    out["horizon"].append(bool(hit[0]))
back = Y_UP_TO_Z_UP.inverted()
out["frames"] = {}
meshes = [o for o in scene.objects if o.type == "MESH" and "mpmfx_clip" in o.modifiers]
for f in range(scene.frame_start, scene.frame_end + 1):
    scene.frame_set(f)
    for clipped in (True, False):
        for o in meshes:
            o.modifiers["mpmfx_clip"].show_viewport = clipped
        dg = bpy.context.evaluated_depsgraph_get()
        for o in meshes:
            ev = o.evaluated_get(dg)
            pts = [back @ (ev.matrix_world @ v.co) for v in ev.data.vertices]
            key = f"{f} {o.name} {'drawn' if clipped else 'imported'}"
            out["frames"][key] = [[min(p[i] for p in pts) for i in range(3)], [max(p[i] for p in pts) for i in range(3)], len(pts)]
print("SCENE " + json.dumps(out))
"""


def test_cycles_scene_world_horizon_and_clipped_surfaces(exported, tmp_path):
    """The Cycles scene is lit by one of Blender's studio HDRIs; from the camera, the ground runs
    on to the horizon (a ray a quarter of a degree below it still meets the ground, all round);
    and no drawn surface lies under the ground or outside the solver's walls, while the imported
    surfaces did (the surfacer's level set reaches past the material)."""
    from mpmfx.render.camera import render_camera, solver_box, solver_floor
    from mpmfx.render.cycles import write_job
    from mpmfx.shotfile import load_shot_config

    _, shot_path, entries = exported
    shot = load_shot_config(shot_path)
    lo, hi = solver_box(shot)
    job = write_job(
        tmp_path / "job.json",
        usd=entries["export"] / "shot.usda",
        frames=[1],
        outputs=[tmp_path / "0001.png"],
        blend=None,
        width=64,
        height=48,
        samples=1,
        denoise=False,
        shutter=0.0,
        fps=24.0,
        mode="surface",
        looks={"Elastic": "jelly", "Water": "water"},
        floor_y=solver_floor(shot),
        domain_origin=shot.domain.origin,
        domain_size=shot.domain.size,
        camera=render_camera(shot),
        sun_elevation=35.0,
        sun_rotation=150.0,
        walls=(lo, hi),
        basin=0.1,
    )
    line = next(s for s in _blender(SCENE, str(job), "0.25").splitlines() if s.startswith("SCENE "))
    seen = json.loads(line.removeprefix("SCENE "))
    assert len(seen["env"]) == 1 and "studiolights" in seen["env"][0] and Path(seen["env"][0]).is_file()
    assert all(seen["horizon"]), seen["horizon"]
    tol = 1e-5
    outside = {}
    for key, (low, high, count) in seen["frames"].items():
        assert count > 0, key
        over = max(max(a - b for a, b in zip(lo, low)), max(a - b for a, b in zip(high, hi)))
        outside[key] = over
    drawn = {k: v for k, v in outside.items() if k.endswith("drawn")}
    assert max(drawn.values()) <= tol, drawn
    # the check means something: the surfaces as imported did cross the floor or a wall
    assert max(v for k, v in outside.items() if k.endswith("imported")) > 10 * tol, outside
    # clamping keeps the topology: the drawn mesh has the imported mesh's vertices
    for key in drawn:
        assert seen["frames"][key][2] == seen["frames"][key.replace("drawn", "imported")][2], key
