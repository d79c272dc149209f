"""Animated assets load as colliders with their motion (mpmfx.geometry.animated): a USD with
time-sampled points or a time-sampled transform, a .blend with an armature; each checked
against Blender's own evaluated vertices at two frames. Bad input names the file."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mpmfx
from mpmfx.blender import bpy_available
from mpmfx.geometry.animated import load_animation
from mpmfx.geometry.common import MeshError
from tests.anim_assets import CUBE, growing_cube_usd

needs_bpy = pytest.mark.skipif(not bpy_available(), reason="bpy (Blender as a module) is not installed")

# Runs inside Blender: import a USD stage, print each frame's evaluated world vertices (Y-up, m).
USD_IN_BLENDER = """
import json, sys
import bpy
import numpy as np
from mpmfx.geometry.common import Z_UP_TO_Y_UP
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=sys.argv[1])
scene = bpy.context.scene
out = {}
for f in json.loads(sys.argv[2]):
    scene.frame_set(f)
    dg = bpy.context.evaluated_depsgraph_get()
    rows = []
    for ob in scene.objects:
        if ob.type == "MESH":
            ev = ob.evaluated_get(dg)
            m = np.array(ev.matrix_world)
            v = np.array([tuple(p.co) for p in ev.data.vertices])
            rows += (v @ m[:3, :3].T + m[:3, 3]).tolist()
    out[f] = (np.array(rows) @ Z_UP_TO_Y_UP).tolist()
print("VERTS " + json.dumps(out))
"""

# Runs inside Blender: a cube skinned to one bone that turns 90 degrees about x over frames
# 1..11; saves the .blend (and, given a second path, exports it as FBX with its animation baked,
# as a rig leaves Maya or Houdini) and prints Blender's evaluated world vertices at two frames
# (Y-up).
ARMATURE = """
import json, math, sys
import bpy
import numpy as np
from mpmfx.geometry.common import Z_UP_TO_Y_UP
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.frame_start, scene.frame_end = 1, 11
bpy.ops.mesh.primitive_cube_add(size=0.4, location=(0.0, 0.0, 0.6))
cube = bpy.context.object
arm_data = bpy.data.armatures.new("rig")
rig = bpy.data.objects.new("rig", arm_data)
scene.collection.objects.link(rig)
bpy.context.view_layer.objects.active = rig
bpy.ops.object.mode_set(mode="EDIT")
bone = arm_data.edit_bones.new("leg")
bone.head, bone.tail = (0.0, 0.0, 0.0), (0.0, 0.0, 0.4)
bpy.ops.object.mode_set(mode="OBJECT")
group = cube.vertex_groups.new(name="leg")
group.add(list(range(len(cube.data.vertices))), 1.0, "REPLACE")
mod = cube.modifiers.new("skin", "ARMATURE")
mod.object = rig
pb = rig.pose.bones["leg"]
pb.rotation_mode = "XYZ"
for f, angle in ((1, 0.0), (11, 90.0)):
    pb.rotation_euler = (math.radians(angle), 0.0, 0.0)
    pb.keyframe_insert("rotation_euler", frame=f)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[1])
if len(sys.argv) > 2:
    bpy.ops.export_scene.fbx(filepath=sys.argv[2], bake_anim=True, add_leaf_bones=False)
out = {}
for f in (3, 8):
    scene.frame_set(f)
    dg = bpy.context.evaluated_depsgraph_get()
    ev = cube.evaluated_get(dg)
    m = np.array(ev.matrix_world)
    mesh = ev.to_mesh()
    v = np.array([tuple(p.co) for p in mesh.vertices])
    ev.to_mesh_clear()
    out[f] = ((v @ m[:3, :3].T + m[:3, 3]) @ Z_UP_TO_Y_UP).tolist()
print("VERTS " + json.dumps(out))
"""


def _blender(script: str, *args: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(Path(mpmfx.__file__).parents[1])}
    res = subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    line = next(s for s in res.stdout.splitlines() if s.startswith("VERTS "))
    return {int(k): np.array(v) for k, v in json.loads(line.removeprefix("VERTS ")).items()}


def _same_points(a, b, tol=1e-4):
    """Equal as sets of points (an importer may order or split vertices its own way)."""
    ua = np.unique(np.round(np.asarray(a) / tol).astype(np.int64), axis=0)
    ub = np.unique(np.round(np.asarray(b) / tol).astype(np.int64), axis=0)
    return ua.shape == ub.shape and np.abs(ua - ub).max() <= 1


@pytest.mark.parametrize("moving", [False, True], ids=["points", "transform"])
def test_a_time_sampled_usd_loads_with_its_motion(tmp_path, moving):
    frames = list(range(1, 11))
    path = growing_cube_usd(
        tmp_path / "walker.usda", centre=(0.1, 0.5, 0.0), half0=0.2, speed=0.6, frames=frames, moving=moving
    )
    anim = load_animation(path, frames, 24.0)
    assert anim.points.shape == (10, 8, 3) and anim.faces.shape == (12, 3)
    for i, f in enumerate(frames):  # what the file says, frame by frame
        t = (f - 1) / 24.0
        want = (0.1 + 0.6 * t * moving, 0.5, 0.0) + CUBE * (0.2 if moving else 0.2 + 0.6 * t)
        assert _same_points(anim.points[i], want)
    if bpy_available():  # and what Blender evaluates from the same stage
        seen = _blender(USD_IN_BLENDER, str(path), json.dumps([3, 8]))
        for f in (3, 8):
            assert _same_points(anim.points[f - 1], seen[f])


@needs_bpy
@pytest.mark.parametrize("suffix", [".blend", ".fbx"])
def test_a_rig_with_an_armature_loads_as_blender_evaluates_it(tmp_path, suffix):
    """The .blend, or the FBX exported from it with its animation baked, loads with the skinned
    cube where Blender's own evaluation of the .blend puts it, at two frames."""
    blend, fbx = tmp_path / "rig.blend", tmp_path / "rig.fbx"
    seen = _blender(ARMATURE, str(blend), str(fbx))
    path = blend if suffix == ".blend" else fbx
    anim = load_animation(path, [3, 8], 24.0)
    assert anim.points.shape[0] == 2 and len(anim.faces) == 12
    for i, f in enumerate((3, 8)):
        assert (
            _same_points(anim.points[i], seen[f], tol=1e-4)
            if suffix == ".fbx"
            else (np.abs(anim.points[i] - seen[f]).max() < 1e-5)
        )
    assert np.abs(anim.points[1] - anim.points[0]).max() > 0.05  # it moved
    with pytest.raises(MeshError, match=rf"rig\{suffix}.*frame range 1\.\.11"):
        load_animation(path, list(range(1, 14)), 24.0)


def test_an_animation_short_of_the_shot_names_the_file(tmp_path):
    path = growing_cube_usd(tmp_path / "walker.usda", centre=(0, 0, 0), half0=0.2, speed=0.6, frames=range(1, 6))
    with pytest.raises(MeshError, match=r"walker\.usda: .*time codes 1\.\.5.*frames 1\.\.8"):
        load_animation(path, range(1, 9), 24.0)


def test_changing_topology_names_the_file_and_frame(tmp_path):
    from pxr import Usd, UsdGeom, Vt

    path = growing_cube_usd(tmp_path / "walker.usda", centre=(0, 0, 0), half0=0.2, speed=0.6, frames=range(1, 6))
    stage = Usd.Stage.Open(str(path))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/walker/body"))
    idx = list(mesh.GetFaceVertexIndicesAttr().Get())
    for f, n in ((1, 6), (4, 5)):  # a face lost at frame 4
        mesh.GetFaceVertexCountsAttr().Set(Vt.IntArray([4] * n), f)
        mesh.GetFaceVertexIndicesAttr().Set(Vt.IntArray(idx[: 4 * n]), f)
    stage.GetRootLayer().Save()
    with pytest.raises(MeshError, match=r"walker\.usda: the mesh's topology changes at frame 4"):
        load_animation(path, range(1, 6), 24.0)
