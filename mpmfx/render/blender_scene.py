"""The lit scene around an imported shot, built with bpy (runs only inside the Blender child
process, `mpmfx.render.cycles_job`; never import this next to pxr).

Coordinates: the USD stage is metres, Y up; Blender's importer turns it Z up by rotating the
root. Everything here that comes from the shot (floor height, camera, bounds) is given in the
stage's frame and converted with `to_blender`, so the two can never drift apart.
"""

from __future__ import annotations

import math
from pathlib import Path

import bmesh
import bpy
from mathutils import Matrix, Vector

from mpmfx.render.looks import DEFAULT_PIXEL_M, LOOKS, sparkle

# USD (x, y, z), Y up  ->  Blender (x, -z, y), Z up: what the importer does for a Y-up stage.
Y_UP_TO_Z_UP = Matrix.Rotation(math.radians(90.0), 4, "X")


def to_blender(p) -> Vector:
    return Y_UP_TO_Z_UP @ Vector(tuple(float(c) for c in p))


# ---------------------------------------------------------------------------------------------
# Materials


def _link(tree, a, b):
    tree.links.new(a, b)


def make_material(name: str, look: str, pixel_m: float = DEFAULT_PIXEL_M) -> bpy.types.Material:
    """A Principled BSDF material from `LOOKS[look]`, with its grain, bump, sparkle, clear
    shadows and absorption; pixel_m: the metres one pixel of the render covers at the subject
    (`mpmfx.render.looks.metres_per_pixel`), which sizes the glints."""
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
        coords = tree.nodes.new("ShaderNodeTexCoord").outputs["Object"]  # object coordinates are metres
        size = (spec.get("bump") or (0.002, 0, 0))[0]
        fac, height = (_cells if spec.get("cells") else _noise)(tree, coords, size)
        if spec.get("grain"):
            ramp = tree.nodes.new("ShaderNodeValToRGB")
            ramp.color_ramp.elements[0].position, ramp.color_ramp.elements[1].position = 0.35, 0.65
            ramp.color_ramp.elements[0].color = (*spec["grain"], 1.0)
            ramp.color_ramp.elements[1].color = (*spec["bsdf"]["Base Color"], 1.0)
            _link(tree, fac, ramp.inputs["Fac"])
            _link(tree, ramp.outputs["Color"], bsdf.inputs["Base Color"])
        if spec.get("bump"):
            _, strength, distance = spec["bump"]
            bump = tree.nodes.new("ShaderNodeBump")
            bump.inputs["Strength"].default_value = strength
            bump.inputs["Distance"].default_value = distance
            _link(tree, height, bump.inputs["Height"])
            _link(tree, bump.outputs["Normal"], bsdf.inputs["Normal"])
    surface = bsdf.outputs["BSDF"]
    glints = sparkle(look, pixel_m)
    if glints:
        surface = _sparkle(tree, surface, *glints)
    if spec.get("clear_shadow"):
        surface = _clear_shadow(tree, surface)
    _link(tree, surface, out.inputs["Surface"])
    if spec.get("absorb"):
        colour, density = spec["absorb"]
        absorb = tree.nodes.new("ShaderNodeVolumeAbsorption")
        absorb.inputs["Color"].default_value = (*colour, 1.0)
        absorb.inputs["Density"].default_value = density
        _link(tree, absorb.outputs["Volume"], out.inputs["Volume"])
    return mat


def _math(tree, op: str, a, b=None, *, vector: bool = False):
    """A Math (or Vector Math) node `op` of sockets or constants a, b; returns its output."""
    node = tree.nodes.new("ShaderNodeVectorMath" if vector else "ShaderNodeMath")
    node.operation = op
    for i, v in enumerate((a, b)):
        if v is None:
            continue
        if isinstance(v, bpy.types.NodeSocket):
            _link(tree, v, node.inputs[i])
        else:
            node.inputs[i].default_value = v
    return node.outputs["Vector" if vector else "Value"]


def _noise(tree, coords, size: float):
    """(colour mix factor, bump height): a smooth noise of feature `size` m."""
    noise = tree.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 1.0 / size
    noise.inputs["Detail"].default_value = 4.0
    _link(tree, coords, noise.inputs["Vector"])
    return noise.outputs["Fac"], noise.outputs["Fac"]


def _cells(tree, coords, size: float):
    """(colour mix factor, bump height) for grains of `size` m: one random value per Voronoi
    cell mixed with a mottle eight grains across; each grain a dome (high at its centre)."""
    cells = tree.nodes.new("ShaderNodeTexVoronoi")
    cells.inputs["Scale"].default_value = 1.0 / size
    _link(tree, coords, cells.inputs["Vector"])
    mottle = tree.nodes.new("ShaderNodeTexNoise")
    mottle.inputs["Scale"].default_value = 1.0 / (8.0 * size)
    _link(tree, coords, mottle.inputs["Vector"])
    each = tree.nodes.new("ShaderNodeSeparateColor")
    _link(tree, cells.outputs["Color"], each.inputs["Color"])
    fac = _math(
        tree,
        "ADD",
        _math(tree, "MULTIPLY", each.outputs["Red"], 0.6),
        _math(tree, "MULTIPLY", mottle.outputs["Fac"], 0.5),
    )
    dome = _math(tree, "SUBTRACT", 1.0, _math(tree, "MULTIPLY", cells.outputs["Distance"], cells.outputs["Distance"]))
    return _math(tree, "SUBTRACT", fac, 0.05), dome


def _sparkle(tree, surface, size: float, core: float, weight: float):
    """`surface` plus sparse glints: in the cores of Voronoi cells of `size` m (within `core`
    cell sizes of the cell's point) a near-mirror glossy facet, tilted at random per cell,
    added at `weight` (added, not mixed: a facet that mirrors something darker than the surface
    must not show as a dark speck)."""
    cells = tree.nodes.new("ShaderNodeTexVoronoi")
    cells.inputs["Scale"].default_value = 1.0 / size
    _link(tree, tree.nodes.new("ShaderNodeTexCoord").outputs["Object"], cells.inputs["Vector"])
    mask = _math(tree, "LESS_THAN", cells.outputs["Distance"], core)
    # tilts up to about 30 degrees each way: a spread of facets, so that some of them mirror the
    # sun towards the camera wherever the surface is lit
    tilt = _math(tree, "SUBTRACT", cells.outputs["Color"], (0.5, 0.5, 0.5), vector=True)
    tilt = _math(tree, "SCALE", tilt, vector=True)
    tilt.node.inputs["Scale"].default_value = 1.2
    normal = tree.nodes.new("ShaderNodeNewGeometry").outputs["Normal"]
    facet = _math(tree, "NORMALIZE", _math(tree, "ADD", normal, tilt, vector=True), vector=True)
    glossy = tree.nodes.new("ShaderNodeBsdfAnisotropic")  # Blender 4.x's Glossy BSDF
    glossy.inputs["Roughness"].default_value = 0.15
    _link(tree, facet, glossy.inputs["Normal"])
    grey = tree.nodes.new("ShaderNodeCombineColor")
    for channel in ("Red", "Green", "Blue"):
        _link(tree, _math(tree, "MULTIPLY", mask, weight), grey.inputs[channel])
    _link(tree, grey.outputs["Color"], glossy.inputs["Color"])
    add = tree.nodes.new("ShaderNodeAddShader")
    _link(tree, surface, add.inputs[0])
    _link(tree, glossy.outputs[0], add.inputs[1])
    return add.outputs["Shader"]


def _clear_shadow(tree, surface):
    """`surface` for camera and bounce rays; shadow rays see it transparent."""
    path = tree.nodes.new("ShaderNodeLightPath")
    clear = tree.nodes.new("ShaderNodeBsdfTransparent")
    mix = tree.nodes.new("ShaderNodeMixShader")
    _link(tree, path.outputs["Is Shadow Ray"], mix.inputs["Fac"])
    _link(tree, surface, mix.inputs[1])
    _link(tree, clear.outputs["BSDF"], mix.inputs[2])
    return mix.outputs["Shader"]


def assign(obj, mat) -> None:
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    for i in range(len(getattr(obj, "material_slots", []))):
        obj.material_slots[i].link = "OBJECT"  # a USD reload re-creates data, not object slots
        obj.material_slots[i].material = mat


# ---------------------------------------------------------------------------------------------
# Ground, sky, sun


def add_ground(floor_y: float, centre, *, size: float, fade: tuple[float, float], world: dict) -> bpy.types.Object:
    """A square ground plane of `size` metres at the solver's floor height (stage y = floor_y),
    fading between `fade` (near, far) metres from the camera into the world's colour at the
    horizon (`world`: `mpmfx.render.looks.WORLD`), so that it meets the sky with no edge."""
    mesh = bpy.data.meshes.new("ground")
    h = size / 2
    mesh.from_pydata([(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)], [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new("ground", mesh)
    bpy.context.scene.collection.objects.link(obj)
    c = to_blender((centre[0], floor_y, centre[2]))
    obj.location = c
    mat = make_material("ground", "ground")
    tree = mat.node_tree
    out = tree.nodes["Material Output"]
    stone = out.inputs["Surface"].links[0].from_socket
    # the horizon in the direction of this point (the view ray, flattened), as the camera sees it
    away = _math(tree, "SCALE", tree.nodes.new("ShaderNodeNewGeometry").outputs["Incoming"], vector=True)
    away.node.inputs["Scale"].default_value = -1.0
    flat = _math(tree, "MULTIPLY", away, (1.0, 1.0, 0.0), vector=True)
    haze = tree.nodes.new("ShaderNodeEmission")
    haze.inputs["Strength"].default_value = world["strength"]
    _link(tree, _environment(tree, _lifted(tree, flat, world), world), haze.inputs["Color"])
    far = tree.nodes.new("ShaderNodeMapRange")
    far.interpolation_type = "SMOOTHSTEP"
    far.inputs["From Min"].default_value, far.inputs["From Max"].default_value = fade
    _link(tree, tree.nodes.new("ShaderNodeCameraData").outputs["View Distance"], far.inputs["Value"])
    mix = tree.nodes.new("ShaderNodeMixShader")
    _link(tree, far.outputs["Result"], mix.inputs["Fac"])
    _link(tree, stone, mix.inputs[1])
    _link(tree, haze.outputs["Emission"], mix.inputs[2])
    _link(tree, mix.outputs["Shader"], out.inputs["Surface"])
    # the haze is the world's colour, already lit: not a light for Cycles to sample (a lamp
    # kilometres wide would take samples from the sun and the sky)
    mat.cycles.emission_sampling = "NONE"
    assign(obj, mat)
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


def studio_hdri(name: str) -> Path:
    """The path of one of the studio HDRIs that Blender ships (datafiles/studiolights/world)."""
    return Path(bpy.utils.system_resource("DATAFILES", path="studiolights/world")) / f"{name}.exr"


def _environment(tree, vector, world: dict):
    """The world's HDRI colour in the direction `vector` (a socket, Blender world axes), turned
    by world["rotation"] degrees about the up axis and clamped to world["clamp"]."""
    image = bpy.data.images.get(world["hdri"]) or bpy.data.images.load(str(studio_hdri(world["hdri"])))
    image.name = world["hdri"]
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    turn = tree.nodes.new("ShaderNodeMapping")
    turn.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(world.get("rotation", 0.0)))
    _link(tree, vector, turn.inputs["Vector"])
    _link(tree, turn.outputs["Vector"], env.inputs["Vector"])
    c = world["clamp"]
    return _math(tree, "MINIMUM", env.outputs["Color"], (c, c, c), vector=True)


def _lifted(tree, direction, world: dict):
    """`direction` tilted up: the horizon moves to world["horizon_lift"] (tan of its elevation)."""
    return _math(
        tree, "NORMALIZE", _math(tree, "ADD", direction, (0.0, 0.0, world["horizon_lift"]), vector=True), vector=True
    )


def add_world(world: dict, *, sun_elevation: float, sun_rotation: float) -> dict:
    """Light the scene with `world` (`mpmfx.render.looks.WORLD`: a studio HDRI, its own sun
    clamped) plus a sun lamp along elevation / rotation (degrees; rotation about the up axis,
    from +Y towards -X): a lamp converges in a few samples and casts the sharp shadows. The HDRI
    is turned so that its sun stands where the lamp is; returns `world` with that "rotation"."""
    scene = bpy.context.scene
    el, rot = math.radians(sun_elevation), math.radians(sun_rotation)
    towards_sun = Vector((-math.sin(rot) * math.cos(el), math.cos(rot) * math.cos(el), math.sin(el)))
    lamp_azimuth = math.degrees(math.atan2(towards_sun.y, towards_sun.x))
    world = {**world, "rotation": world["sun_azimuth"] - lamp_azimuth}
    bw = scene.world or bpy.data.worlds.new("World")
    scene.world = bw
    bw.use_nodes = True
    tree = bw.node_tree
    tree.nodes.clear()
    bg = tree.nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = world["strength"]
    out = tree.nodes.new("ShaderNodeOutputWorld")
    direction = tree.nodes.new("ShaderNodeTexCoord").outputs["Generated"]  # world: the view direction
    # The camera sees the sky over the skyline (the view lifted, as the ground's haze is), so the
    # picture's top meets the ground's far edge in one colour; reflections see the whole HDRI.
    pick = tree.nodes.new("ShaderNodeMix")
    pick.data_type = "VECTOR"
    _link(tree, tree.nodes.new("ShaderNodeLightPath").outputs["Is Camera Ray"], pick.inputs["Factor"])
    _link(tree, direction, pick.inputs["A"])
    _link(tree, _lifted(tree, direction, world), pick.inputs["B"])
    _link(tree, _environment(tree, pick.outputs["Result"], world), bg.inputs["Color"])
    _link(tree, bg.outputs["Background"], out.inputs["Surface"])
    lamp = bpy.data.lights.new("sun", "SUN")
    lamp.energy = world["sun_strength"]
    lamp.angle = math.radians(3.0)  # a slightly soft sun: softer contact shadows
    sun = bpy.data.objects.new("sun", lamp)
    scene.collection.objects.link(sun)
    sun.rotation_euler = towards_sun.to_track_quat("Z", "Y").to_euler()
    return world


# ---------------------------------------------------------------------------------------------
# Clipping


def clip_to_box(obj, lo, hi) -> None:
    """Hold every vertex of `obj` inside the box [lo, hi] (stage metres): a Geometry Nodes
    modifier after the USD cache moves a vertex outside onto the nearest face of the box.

    The surfacer's level set reaches a particle radius past the material, so a surface at rest
    on the solver's floor or against its walls pokes through the ground or the tank's glass;
    clamped, it meets them flat. The topology (and the vertex count, and the velocities) stay."""
    # the box in the object's own frame (its transform is the importer's Y-up rotation)
    bpy.context.view_layer.update()
    inv = obj.matrix_world.inverted()
    corners = [inv @ to_blender((x, y, z)) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    low = tuple(min(c[i] for c in corners) for i in range(3))
    high = tuple(max(c[i] for c in corners) for i in range(3))
    group = bpy.data.node_groups.new(f"mpmfx_clip_{obj.name}", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes = group.nodes
    inside = _math(
        group,
        "MINIMUM",
        _math(group, "MAXIMUM", nodes.new("GeometryNodeInputPosition").outputs[0], low, vector=True),
        high,
        vector=True,
    )
    move = nodes.new("GeometryNodeSetPosition")
    _link(group, nodes.new("NodeGroupInput").outputs[0], move.inputs["Geometry"])
    _link(group, inside, move.inputs["Position"])
    _link(group, move.outputs["Geometry"], nodes.new("NodeGroupOutput").inputs[0])
    obj.modifiers.new("mpmfx_clip", "NODES").node_group = group


# ---------------------------------------------------------------------------------------------
# Camera


def add_camera(position, look_at, *, focal_mm: float = 35.0, film_mm: float = 36.0) -> bpy.types.Object:
    """A camera at `position` looking at `look_at` (stage metres), `film_mm` wide, horizontal fit."""
    cam = bpy.data.cameras.new("render_camera")
    cam.lens, cam.sensor_width, cam.sensor_fit = focal_mm, film_mm, "HORIZONTAL"
    cam.clip_start, cam.clip_end = 0.01, 1.0e5  # the ground runs kilometres to the horizon
    obj = bpy.data.objects.new("render_camera", cam)
    bpy.context.scene.collection.objects.link(obj)
    pos, target = to_blender(position), to_blender(look_at)
    obj.location = pos
    obj.rotation_euler = (target - pos).to_track_quat("-Z", "Y").to_euler()
    return obj
