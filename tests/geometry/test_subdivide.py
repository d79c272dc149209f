"""Catmull-Clark against the real thing: Blender's Subdivision Surface modifier (OpenSubdiv, in
Blender's own process), on a closed cube with creases and corners and on an open grid."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial import cKDTree

from mpmfx.blender import bpy_available
from mpmfx.geometry.subdivide import Creases, catmull_clark

CUBE_V = [[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]
CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
TOP = [(1, 3), (3, 7), (7, 5), (5, 1)]  # the z = 1 face's edges
# an open, wavy L-shaped grid: a boundary with a concave corner
GRID_V = [[x, y, 0.3 * math.sin(x) * math.cos(y)] for x in range(4) for y in range(4)]
GRID_F = [
    [x * 4 + y, (x + 1) * 4 + y, (x + 1) * 4 + y + 1, x * 4 + y + 1]
    for x in range(3)
    for y in range(3)
    if not (x == 2 and y == 2)
]
# (case, mesh, edge sharpness of TOP or None, sharpness of corner vertex 7 or None)
CASES = [
    ("smooth cube", "cube", None, None),
    ("creased for good", "cube", 10.0, None),
    ("creased 1.5", "cube", 1.5, None),
    ("creased 0.5", "cube", 0.5, None),
    ("sharp corner", "cube", None, 10.0),
    ("open grid", "grid", None, None),
]

# Runs inside Blender: each case at levels 1-3. Blender's crease c is OpenSubdiv sharpness 10 c^2.
BLENDER = """
import json, math, sys
import bpy
cases, meshes, top = json.loads(sys.argv[1]), json.loads(sys.argv[2]), json.loads(sys.argv[3])
bpy.ops.wm.read_factory_settings(use_empty=True)
out = {}
for name, mesh, edge, corner in cases:
    for level in (1, 2, 3):
        me = bpy.data.meshes.new("m")
        me.from_pydata(*meshes[mesh])
        me.update()
        if edge is not None:
            attr = me.attributes.new("crease_edge", "FLOAT", "EDGE")
            for i, e in enumerate(me.edges):
                if sorted(e.vertices) in [sorted(p) for p in top]:
                    attr.data[i].value = math.sqrt(edge / 10.0)
        if corner is not None:
            me.attributes.new("crease_vert", "FLOAT", "POINT").data[7].value = math.sqrt(corner / 10.0)
        ob = bpy.data.objects.new("o", me)
        bpy.context.collection.objects.link(ob)
        mod = ob.modifiers.new("s", "SUBSURF")
        mod.levels, mod.use_limit_surface, mod.boundary_smooth, mod.use_creases = level, False, "PRESERVE_CORNERS", True
        ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
        out[f"{name} {level}"] = [list(v.co) for v in ev.to_mesh().vertices]
        ev.to_mesh_clear()
        bpy.data.objects.remove(ob)
print("VERTICES " + json.dumps(out))
"""


@pytest.fixture(scope="module")
def opensubdiv():
    if not bpy_available():
        pytest.fail("bpy (Blender as a module) is part of the test set-up: bash setup.sh test installs it")
    meshes = {"cube": [CUBE_V, [], CUBE_F], "grid": [GRID_V, [], GRID_F]}
    res = subprocess.run(
        [sys.executable, "-c", BLENDER, json.dumps(CASES), json.dumps(meshes), json.dumps(TOP)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    line = next(s for s in res.stdout.splitlines() if s.startswith("VERTICES "))
    return {k: np.array(v) for k, v in json.loads(line.removeprefix("VERTICES ")).items()}


@pytest.mark.parametrize("level", [1, 2, 3])
@pytest.mark.parametrize("name, mesh, edge, corner", CASES)
def test_the_same_vertices_as_opensubdiv(opensubdiv, name, mesh, edge, corner, level):
    v, f = (CUBE_V, CUBE_F) if mesh == "cube" else (GRID_V, GRID_F)
    creases = Creases()
    if edge is not None:
        creases = Creases(pairs=np.array(TOP), sharpness=np.full(len(TOP), edge))
    if corner is not None:
        creases = Creases(corners=np.array([7]), corner_sharpness=np.array([corner]))
    ours, counts, _, parent = catmull_clark(
        np.array(v, float), np.full(len(f), 4), np.array(f).ravel(), creases=creases, levels=level
    )
    theirs = opensubdiv[f"{name} {level}"]
    assert len(ours) == len(theirs) and len(counts) == len(f) * 4**level and len(parent) == len(counts)
    # vertex order differs: every vertex of each lies on one of the other's (Blender's are float32)
    assert cKDTree(theirs).query(ours)[0].max() < 1e-6
    assert cKDTree(ours).query(theirs)[0].max() < 1e-6
