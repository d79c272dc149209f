"""The meshes of a Blender (.blend), FBX or compressed glTF file as Cycles would render them, for
mpmfx.geometry.mesh: Blender opens the file in its own process (it bundles its own USD
libraries, so bpy never shares a process with pxr) and writes the triangles to an .npz.

    python -m mpmfx.geometry.blender_export IN.blend|IN.fbx|IN.glb OUT.npz [--frames=F1,F2,..@FPS] [PART]

PART: the name of an object or collection to take alone (the object, what it instances, the
collection's objects however deeply nested); all of the scene without it.

What comes out: every object that renders as a surface (meshes, curves, text, surfaces,
metaballs), with its modifiers at their render settings (a subdivision at its render levels),
every instance (collection instances, particle and geometry-node instances, array modifiers)
at its own transform; objects and collections disabled for rendering left out. Lengths are
metres (the scene's unit scale applied; Blender's FBX importer applies the file's unit) in our
Y-up world: Blender's Z-up (x, y, z) becomes (x, z, -y), as its own USD and glTF exporters do.
OUT holds vertices (n, 3) float64 and faces (f, 3) int64, wound outward as Blender winds them.
With --frames (shot frames of FPS; for animated colliders, mpmfx.geometry.animated) the scene is
evaluated at each, Blender frame F * scene fps / FPS (scene.frame_set, subframes kept), and OUT
holds every frame's vertices and faces one after another, with counts (frames, 2): each frame's
vertex and face count; a frame outside the scene's frame range is an error.
"""

from __future__ import annotations

import sys

import bpy
import numpy as np

from mpmfx.blender import ERROR
from mpmfx.geometry.common import Z_UP_TO_Y_UP

SURFACES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}  # object types Blender turns into a mesh


def open_file(path: str) -> None:
    if path.lower().endswith(".blend"):
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
        return
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if path.lower().endswith((".glb", ".gltf")):  # a compressed glTF (Draco, meshopt): Blender decodes it
        bpy.ops.import_scene.gltf(filepath=path)
    else:
        bpy.ops.import_scene.fbx(filepath=path)
    keyed = [a.frame_range for a in bpy.data.actions]
    if keyed:  # an imported file's animation spans its actions' keys (the empty scene's range is 1..250)
        scene = bpy.context.scene
        scene.frame_start = int(np.floor(min(r[0] for r in keyed)))
        scene.frame_end = int(np.ceil(max(r[1] for r in keyed)))


def as_rendered() -> None:
    """Make the viewport's evaluation the render's: visibility and modifier settings."""
    for coll in bpy.data.collections:
        coll.hide_viewport = coll.hide_render
    for ob in bpy.context.scene.objects:
        ob.hide_viewport = ob.hide_render
        if not ob.hide_render:
            ob.hide_set(False)  # the eye icon hides in viewports only
        for mod in ob.modifiers:
            mod.show_viewport = mod.show_render
            if mod.type in {"SUBSURF", "MULTIRES"}:
                mod.levels = mod.render_levels


def part_objects(part: str | None) -> set[str] | None:
    """Names of the objects `part` takes: the object of that name and every object of the
    collection of that name, however deeply nested (None: everything)."""
    if part is None:
        return None
    names = {part} if part in bpy.data.objects else set()
    if part in bpy.data.collections:
        names |= {ob.name for ob in bpy.data.collections[part].all_objects}
    return names


def triangles(chosen: set[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3) float64 in Blender's world units and axes, faces (f, 3) int64) of
    everything, or of the objects named in `chosen` and what they instance."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    verts, faces, offset = [], [], 0
    for inst in depsgraph.object_instances:
        ob = inst.object
        owner = inst.parent if inst.is_instance and inst.parent else ob  # an instance belongs to its instancer
        if ob.type not in SURFACES or (
            chosen is not None and ob.original.name not in chosen and owner.original.name not in chosen
        ):
            continue
        mesh = ob.to_mesh()
        try:
            mesh.calc_loop_triangles()
            v = np.empty(3 * len(mesh.vertices), np.float64)
            mesh.vertices.foreach_get("co", v)
            t = np.empty(3 * len(mesh.loop_triangles), np.int64)
            mesh.loop_triangles.foreach_get("vertices", t)
        finally:
            ob.to_mesh_clear()
        if len(t) == 0:
            continue
        m = np.array(inst.matrix_world, dtype=float)  # column vectors: p_world = M p
        t = t.reshape(-1, 3)
        if np.linalg.det(m[:3, :3]) < 0:  # a mirroring transform flips the winding
            t = t[:, ::-1]
        verts.append(v.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])
        faces.append(t + offset)
        offset += len(v) // 3
    if not faces:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return np.concatenate(verts), np.concatenate(faces)


def frames_of(arg: str) -> tuple[list[float], float]:
    """'--frames=1,2,3@24' -> ([1, 2, 3], 24.0)."""
    frames, fps = arg.removeprefix("--frames=").split("@")
    return [float(f) for f in frames.split(",")], float(fps)


def evaluated_frames(chosen: set[str] | None, frames: list[float], fps: float):
    """(vertices, faces) of `triangles` at each shot frame, or an error line where a frame lies
    outside the scene's frame range."""
    scene = bpy.context.scene
    rate = scene.render.fps / scene.render.fps_base / fps
    want = [f * rate for f in frames]
    if want[0] < scene.frame_start - 1e-6 or want[-1] > scene.frame_end + 1e-6:
        return (
            f"the animation's frame range {scene.frame_start}..{scene.frame_end} does not cover the shot's "
            f"frames {frames[0]:g}..{frames[-1]:g} (Blender frames {want[0]:g}..{want[-1]:g}): extend the "
            "scene's frame range or change shot.frame_start / frame_end"
        )
    out = []
    for f in want:
        whole = int(np.floor(f))
        scene.frame_set(whole, subframe=float(f - whole))
        out.append(triangles(chosen))
    return out


def main(argv: list[str]) -> int:
    frames = next((a for a in argv[2:] if a.startswith("--frames=")), None)
    argv = [a for a in argv if a != frames]
    src, out, part = argv[0], argv[1], (argv[2] if len(argv) > 2 else None)
    try:
        open_file(src)
    except RuntimeError as exc:  # Blender's operators raise RuntimeError("Error: ...") for a bad file
        print(f"{ERROR}{' '.join(str(exc).split())}", flush=True)
        return 1
    if part is not None and part not in bpy.data.objects and part not in bpy.data.collections:
        names = sorted(o.name for o in bpy.context.scene.objects if o.type in SURFACES)[:12]
        print(f"{ERROR}no object or collection named '{part}'; its surfaces: {', '.join(names) or 'none'}", flush=True)
        return 1
    as_rendered()
    unit = bpy.context.scene.unit_settings.scale_length
    if frames is not None:
        each = evaluated_frames(part_objects(part), *frames_of(frames))
        if isinstance(each, str):
            print(f"{ERROR}{each}", flush=True)
            return 1
        counts = np.array([[len(v), len(f)] for v, f in each], np.int64)
        with open(out, "wb") as fh:
            np.savez(
                fh,
                vertices=np.concatenate([v for v, _ in each]) * unit @ Z_UP_TO_Y_UP,
                faces=np.concatenate([f for _, f in each]),
                counts=counts,
            )
        return 0
    v, f = triangles(part_objects(part))
    v = v * unit @ Z_UP_TO_Y_UP
    with open(out, "wb") as fh:  # a file object: np.savez would add .npz to a name without it
        np.savez(fh, vertices=v, faces=f)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
