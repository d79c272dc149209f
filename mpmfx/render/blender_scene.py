"""The lit scene around an imported shot, built with bpy (runs only inside the Blender child
process, `mpmfx.render.cycles_job`; never import this next to pxr).

Coordinates: the USD stage is metres, Y up; Blender's importer turns it Z up by rotating the
root. Everything here that comes from the shot (floor height, camera, bounds) is given in the
stage's frame and converted with `to_blender`, so the two can never drift apart.
"""

from __future__ import annotations

import math

import bmesh
import bpy
from mathutils import Matrix, Vector

from mpmfx.render.camera import frame_box
from mpmfx.render.looks import LOOKS

# USD (x, y, z), Y up  ->  Blender (x, -z, y), Z up: what the importer does for a Y-up stage.
Y_UP_TO_Z_UP = Matrix.Rotation(math.radians(90.0), 4, "X")


def to_blender(p) -> Vector:
    return Y_UP_TO_Z_UP @ Vector(tuple(float(c) for c in p))


# ---------------------------------------------------------------------------------------------
# Materials


def _link(tree, a, b):
    tree.links.new(a, b)


def make_material(name: str, look: str) -> bpy.types.Material:
    """A Principled BSDF material from `LOOKS[look]`, with its grain, bump and absorption."""
    spec = LOOKS[look]
    mat = bpy.data.materials.new(f"mpmfx_{name}")
    mat.use_nodes = True
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    out = tree.nodes["Material Output"]
    for key, value in spec["bsdf"].items():
        bsdf.inputs[key].default_value = (*value, 1.0) if key == "Base Color" else value
    bsdf.subsurface_method = "BURLEY"  # about half the time of random walk on the CPU, same read at this scale
    if spec.get("grain") or spec.get("bump"):
        size = (spec.get("bump") or (0.002, 0, 0))[0]
        coords = tree.nodes.new("ShaderNodeTexCoord")
        noise = tree.nodes.new("ShaderNodeTexNoise")
        noise.inputs["Scale"].default_value = 1.0 / size  # object coordinates are metres
        noise.inputs["Detail"].default_value = 4.0
        _link(tree, coords.outputs["Object"], noise.inputs["Vector"])
        if spec.get("grain"):
            ramp = tree.nodes.new("ShaderNodeValToRGB")
            ramp.color_ramp.elements[0].position, ramp.color_ramp.elements[1].position = 0.35, 0.65
            ramp.color_ramp.elements[0].color = (*spec["grain"], 1.0)
            ramp.color_ramp.elements[1].color = (*spec["bsdf"]["Base Color"], 1.0)
            _link(tree, noise.outputs["Fac"], ramp.inputs["Fac"])
            _link(tree, ramp.outputs["Color"], bsdf.inputs["Base Color"])
        if spec.get("bump"):
            _, strength, distance = spec["bump"]
            bump = tree.nodes.new("ShaderNodeBump")
            bump.inputs["Strength"].default_value = strength
            bump.inputs["Distance"].default_value = distance
            _link(tree, noise.outputs["Fac"], bump.inputs["Height"])
            _link(tree, bump.outputs["Normal"], bsdf.inputs["Normal"])
    if spec.get("clear_shadow"):
        _clear_shadow(tree, bsdf, out)
    if spec.get("absorb"):
        colour, density = spec["absorb"]
        absorb = tree.nodes.new("ShaderNodeVolumeAbsorption")
        absorb.inputs["Color"].default_value = (*colour, 1.0)
        absorb.inputs["Density"].default_value = density
        _link(tree, absorb.outputs["Volume"], out.inputs["Volume"])
    return mat


def _clear_shadow(tree, bsdf, out) -> None:
    """Shadow rays see a transparent surface, camera and bounce rays the BSDF."""
    path = tree.nodes.new("ShaderNodeLightPath")
    clear = tree.nodes.new("ShaderNodeBsdfTransparent")
    mix = tree.nodes.new("ShaderNodeMixShader")
    _link(tree, path.outputs["Is Shadow Ray"], mix.inputs["Fac"])
    _link(tree, bsdf.outputs["BSDF"], mix.inputs[1])
    _link(tree, clear.outputs["BSDF"], mix.inputs[2])
    _link(tree, mix.outputs["Shader"], out.inputs["Surface"])


def assign(obj, mat) -> None:
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    for i in range(len(getattr(obj, "material_slots", []))):
        obj.material_slots[i].link = "OBJECT"  # a USD reload re-creates data, not object slots
        obj.material_slots[i].material = mat


# ---------------------------------------------------------------------------------------------
# Ground, sky, sun


def add_ground(floor_y: float, centre, *, size: float) -> bpy.types.Object:
    """A square ground plane of `size` metres at the solver's floor height (stage y = floor_y)."""
    mesh = bpy.data.meshes.new("ground")
    h = size / 2
    mesh.from_pydata([(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)], [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new("ground", mesh)
    bpy.context.scene.collection.objects.link(obj)
    c = to_blender((centre[0], floor_y, centre[2]))
    obj.location = c
    assign(obj, make_material("ground", "ground"))
    return obj


def add_basin(lo, hi, *, height: float, thickness: float, look: str = "ground") -> bpy.types.Object:
    """Four walls of `height` m (stone, or the look named) standing on the floor just outside the
    box [lo, hi] (stage metres), where the solver's side walls hold a pool: the water meets a
    wall, not thin air."""
    bm = bmesh.new()
    x0, y0, z0 = lo
    x1, _, z1 = hi
    t = thickness
    for a, b in (
        ((x0 - t, z0 - t), (x1 + t, z0)),
        ((x0 - t, z1), (x1 + t, z1 + t)),
        ((x0 - t, z0), (x0, z1)),
        ((x1, z0), (x1 + t, z1)),
    ):
        centre = to_blender(((a[0] + b[0]) / 2, y0 + height / 2, (a[1] + b[1]) / 2))
        size = Vector((b[0] - a[0], b[1] - a[1], height))  # Blender axes: x, y (= -stage z), z up
        geom = bmesh.ops.create_cube(bm, size=1.0)["verts"]
        bmesh.ops.scale(bm, vec=size, verts=geom)
        bmesh.ops.translate(bm, vec=centre, verts=geom)
    mesh = bpy.data.meshes.new("basin")
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new("basin", mesh)
    bpy.context.scene.collection.objects.link(obj)
    assign(obj, make_material("basin", look))
    return obj


def add_sky(*, sun_elevation: float, sun_rotation: float, strength: float = 0.25, sun_strength: float = 3.5) -> None:
    """Blender's Nishita sky for the background and fill light, plus a sun lamp along the sky's
    sun direction (a lamp converges in a few samples; the sky's own sun disc would be noise)."""
    scene = bpy.context.scene
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    world.use_nodes = True
    tree = world.node_tree
    tree.nodes.clear()
    sky = tree.nodes.new("ShaderNodeTexSky")
    sky.sky_type = "NISHITA"
    sky.sun_disc = False
    sky.sun_elevation, sky.sun_rotation = math.radians(sun_elevation), math.radians(sun_rotation)
    bg = tree.nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = strength
    out = tree.nodes.new("ShaderNodeOutputWorld")
    _link(tree, sky.outputs["Color"], bg.inputs["Color"])
    _link(tree, bg.outputs["Background"], out.inputs["Surface"])
    lamp = bpy.data.lights.new("sun", "SUN")
    lamp.energy = sun_strength
    lamp.angle = math.radians(3.0)  # a slightly soft sun: softer contact shadows
    sun = bpy.data.objects.new("sun", lamp)
    scene.collection.objects.link(sun)
    # The lamp comes from elevation / rotation (rotation about the up axis, from +Y towards -X);
    # the sky takes the same two angles for its gradient (its own sun disc is off).
    el, rot = math.radians(sun_elevation), math.radians(sun_rotation)
    towards_sun = Vector((-math.sin(rot) * math.cos(el), math.cos(rot) * math.cos(el), math.sin(el)))
    sun.rotation_euler = towards_sun.to_track_quat("Z", "Y").to_euler()


# ---------------------------------------------------------------------------------------------
# Camera


def add_camera(position, look_at, *, focal_mm: float = 35.0) -> bpy.types.Object:
    """A camera at `position` looking at `look_at` (stage metres), 36 mm film, horizontal fit."""
    cam = bpy.data.cameras.new("render_camera")
    cam.lens, cam.sensor_width, cam.sensor_fit = focal_mm, 36.0, "HORIZONTAL"
    cam.clip_start, cam.clip_end = 0.01, 1000.0
    obj = bpy.data.objects.new("render_camera", cam)
    bpy.context.scene.collection.objects.link(obj)
    pos, target = to_blender(position), to_blender(look_at)
    obj.location = pos
    obj.rotation_euler = (target - pos).to_track_quat("-Z", "Y").to_euler()
    return obj


def frame_bounds(lo, hi, *, direction, aspect: float):
    """(position, look_at) in stage metres that fit the box [lo, hi] in the picture: the same
    framing as a wedge's shared camera (`mpmfx.render.camera.frame_box`)."""
    return frame_box(lo, hi, direction=direction, aspect=aspect)
