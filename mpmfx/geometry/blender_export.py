"""The meshes of a Blender (.blend), FBX or compressed glTF file as Cycles would render them, for
mpmfx.geometry.mesh: Blender opens the file in its own process (it bundles its own USD
libraries, so bpy never shares a process with pxr) and writes the triangles to an .npz.

    python -m mpmfx.geometry.blender_export IN.blend|IN.fbx|IN.glb OUT.npz [PART]

PART: the name of an object or collection to take alone (the object, what it instances, the
collection's objects however deeply nested); all of the scene without it.

What comes out: every object that renders as a surface (meshes, curves, text, surfaces,
metaballs), with its modifiers at their render settings (a subdivision at its render levels),
every instance (collection instances, particle and geometry-node instances, array modifiers)
at its own transform; objects and collections disabled for rendering left out. Lengths are
metres (the scene's unit scale applied; Blender's FBX importer applies the file's unit) in our
Y-up world: Blender's Z-up (x, y, z) becomes (x, z, -y), as its own USD and glTF exporters do.
OUT holds vertices (n, 3) float64 and faces (f, 3) int64, wound outward as Blender winds them.
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


def main(argv: list[str]) -> int:
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
    v, f = triangles(part_objects(part))
    v = v * bpy.context.scene.unit_settings.scale_length @ Z_UP_TO_Y_UP
    with open(out, "wb") as fh:  # a file object: np.savez would add .npz to a name without it
        np.savez(fh, vertices=v, faces=f)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
