"""Render a shot's exported USD stage with Blender's Cycles, in Blender's own process.

    python -m mpmfx.render.cycles_job JOB.json

Blender (`bpy`) and usd-core each bundle their own USD libraries, so this module (with
`mpmfx.render.blender_scene`) imports bpy, never pxr, and no module of the parent imports it
(`mpmfx.blender`): the render stage writes a small JSON job (`mpmfx.render.cycles.write_job`
documents its keys) and runs this as a child process.

The stage is opened with Blender's own USD importer (`bpy.ops.wm.usd_import`), so every
render also proves that the USD works in a DCC. Per frame, stdout gets one line
`MPMFX_FRAME <frame> <wall s> <cpu s, all threads>` after the PNG is in place (the parent turns those into a
progress bar); anything else on stdout/stderr is Blender's own chatter.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

import bpy
from mathutils import Vector

from mpmfx.blender import FRAME_LINE, NOTE_LINE
from mpmfx.render import blender_scene as bs
from mpmfx.render.blender_scene import Y_UP_TO_Z_UP, assign, make_material
from mpmfx.render.looks import GROUND_FADE, GROUND_MIN, GROUND_SPAN, WORLD


def import_stage(usd: str) -> dict[str, list]:
    """Import the USD stage and sort what came in: {"meshes", "points", "volumes", "colliders",
    "cameras"} -> [(prim name, object)]. The prim name is the object / surface group name
    (the parent prim's name: /World/<name>/mesh) or the collider's own name."""
    res = bpy.ops.wm.usd_import(
        filepath=usd,
        set_frame_range=True,
        merge_parent_xform=False,
        import_lights=False,
        import_materials=False,
        relative_path=False,
        create_world_material=False,
    )
    if res != {"FINISHED"}:
        raise RuntimeError(f"{usd}: Blender's USD importer did not finish ({res})")
    out: dict[str, list] = {k: [] for k in ("meshes", "points", "volumes", "colliders", "cameras")}
    for obj in bpy.data.objects:
        parent = _prim_name(obj.parent) if obj.parent else ""
        if obj.type == "CAMERA":
            out["cameras"].append((_prim_name(obj), obj))
        elif obj.type == "MESH" and parent == "colliders":
            out["colliders"].append((_prim_name(obj), obj))
        elif obj.type == "MESH":
            out["meshes"].append((parent, obj))
        elif obj.type == "POINTCLOUD":
            out["points"].append((parent, obj))
        elif obj.type == "VOLUME":
            out["volumes"].append((parent, obj))
    return out


def _prim_name(obj) -> str:
    """The USD prim name of an imported object: Blender appends .001 to repeated names."""
    head, dot, tail = obj.name.rpartition(".")
    return head if dot and tail.isdigit() else obj.name


def scene_bounds(objects, frames: list[int]):
    """(lo, hi) stage metres (Y up) of `objects` over `frames` (at most 12 of them sampled)."""
    scene = bpy.context.scene
    back = Y_UP_TO_Z_UP.inverted()
    lo, hi = [math.inf] * 3, [-math.inf] * 3
    picks = sorted({frames[round(i * (len(frames) - 1) / 11)] for i in range(12)}) if len(frames) > 12 else frames
    for f in picks:
        scene.frame_set(f)
        dg = bpy.context.evaluated_depsgraph_get()
        for obj in objects:
            ev = obj.evaluated_get(dg)
            if not getattr(ev.data, "vertices", None):
                continue
            for corner in ev.bound_box:
                p = back @ (ev.matrix_world @ Vector(corner))
                lo = [min(a, b) for a, b in zip(lo, p)]
                hi = [max(a, b) for a, b in zip(hi, p)]
    return (lo, hi) if lo[0] < math.inf else None


def set_looks(job: dict, imported: dict) -> None:
    """Materials per look; surface mode shows the meshes, particles mode the points; volumes
    (the .vdb level sets) stay in the file for the artist but out of the picture."""
    made: dict[str, object] = {}

    def material(look):
        if look not in made:
            made[look] = make_material(look, look)
        return made[look]

    particles = job["mode"] == "particles"
    for kind, show in (("meshes", not particles), ("points", particles)):
        for name, obj in imported[kind]:
            obj.hide_render = not show
            if show:
                assign(obj, material(job["looks"].get(name, "plastic")))
    for _, obj in imported["volumes"]:
        obj.hide_render = True
    for _, obj in imported["colliders"]:
        assign(obj, material("collider"))


GPU_BACKENDS = ("OPTIX", "CUDA", "HIP", "ONEAPI", "METAL")  # Cycles' GPU device types, preferred first


def use_gpu() -> str | None:
    """Make Cycles render on the first GPU backend with a device here; its name, or None (no
    backend in this Blender build, or no device for any: the CPU renders)."""
    prefs = bpy.context.preferences.addons["cycles"].preferences
    for kind in GPU_BACKENDS:
        try:
            prefs.compute_device_type = kind
        except TypeError:  # not in this build (e.g. Metal off macOS)
            continue
        prefs.refresh_devices()
        found = [d for d in prefs.devices if d.type == kind]
        if found:
            for d in prefs.devices:
                d.use = d.type == kind
            return f"{kind} ({', '.join(d.name for d in found)})"
    prefs.compute_device_type = "NONE"
    return None


def set_render(job: dict) -> None:
    """Cycles on the CPU, or a GPU as the job asks and Blender finds one: samples,
    OpenImageDenoise, motion blur from the exported velocities."""
    scene = bpy.context.scene
    r, c = scene.render, scene.cycles
    r.engine = "CYCLES"
    c.device = "CPU"
    if job.get("device") == "gpu":
        gpu = use_gpu()
        if gpu:
            c.device = "GPU"
            print(f"{NOTE_LINE} Cycles renders on {gpu}", flush=True)
        else:
            print(
                f"{NOTE_LINE} render.device = gpu: Blender finds no OptiX, CUDA, HIP, oneAPI or Metal device "
                "on this machine; Cycles renders on the CPU (set render.device = cpu to skip this check)",
                flush=True,
            )
    c.samples = int(job["samples"])
    c.use_adaptive_sampling = True
    c.use_denoising = bool(job["denoise"])
    if job["denoise"]:
        c.denoiser = "OPENIMAGEDENOISE"
    c.max_bounces, c.diffuse_bounces, c.glossy_bounces = 16, 2, 4
    c.transmission_bounces, c.transparent_max_bounces, c.volume_bounces = 16, 8, 0
    c.caustics_reflective = c.caustics_refractive = False
    c.blur_glossy = 1.0
    r.resolution_x, r.resolution_y, r.resolution_percentage = int(job["width"]), int(job["height"]), 100
    r.fps, r.fps_base = round(job["fps"]), round(job["fps"]) / job["fps"]
    # Meshes carry `velocity` per vertex (the USD export's velocities): Cycles blurs them along it.
    r.use_motion_blur = job["shutter"] > 0
    r.motion_blur_shutter = max(job["shutter"], 1e-3)
    r.use_persistent_data = True  # shaders and the unchanged scene stay compiled between frames
    r.image_settings.file_format, r.image_settings.color_mode = "PNG", "RGB"
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.look = "AgX - Medium High Contrast"
    if job.get("label"):  # a variant (--set) says which one it is, burned into every frame
        for flag in [a for a in dir(r) if a.startswith("use_stamp_")]:
            setattr(r, flag, False)
        r.use_stamp = r.use_stamp_frame = r.use_stamp_note = True
        r.stamp_note_text = job["label"]


def build_scene(job: dict) -> None:
    """Import the stage, then add looks, ground, sky, camera and the render settings."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    imported = import_stage(job["usd"])
    set_looks(job, imported)
    scene = bpy.context.scene
    dom_lo, dom_size = job["domain_origin"], job["domain_size"]
    centre = [o + dom_size / 2 for o in dom_lo]
    world = bs.add_world(WORLD, sun_elevation=job["sun_elevation"], sun_rotation=job["sun_rotation"])
    fade = tuple(f * dom_size for f in GROUND_FADE)
    bs.add_ground(job["floor_y"], centre, size=max(GROUND_SPAN * dom_size, GROUND_MIN), fade=fade, world=world)
    if job.get("walls"):  # no surface under the drawn ground or through the drawn walls
        for _, obj in imported["meshes"]:
            bs.clip_to_box(obj, *job["walls"])
    if job.get("basin") and job.get("walls"):
        look = job["looks"].get("basin", "ground")
        # glass as thin as an aquarium's (thick glass would bend the view of the water)
        bs.add_basin(
            *job["walls"], height=job["basin"], thickness=(0.012 if look == "glass" else 0.04) * dom_size, look=look
        )
    cam = job.get("camera")
    if cam is None:
        shown = [o for _, o in imported["points" if job["mode"] == "particles" else "meshes"]]
        # the stage's whole frame range, not the frames asked for: a resumed or partial render
        # keeps the camera of the full one
        bounds = scene_bounds(
            shown + [o for _, o in imported["colliders"]], list(range(scene.frame_start, scene.frame_end + 1))
        )
        if bounds is None:  # nothing visible anywhere: frame the domain
            bounds = (dom_lo, [o + dom_size for o in dom_lo])
        lo, hi = bounds
        lo = [lo[0], min(lo[1], job["floor_y"]), lo[2]]  # keep the ground contact in the picture
        pos, look = bs.frame_bounds(lo, hi, direction=job["view_direction"], aspect=job["width"] / job["height"])
        cam = {"position": pos, "look_at": look}
    scene.camera = bs.add_camera(cam["position"], cam["look_at"])
    set_render(job)


def render_frames(job: dict) -> None:
    """Render each frame to its PNG (written to a temp name, then renamed: complete or absent)."""
    scene = bpy.context.scene
    for frame, path in zip(job["frames"], job["outputs"]):
        t0, c0 = time.perf_counter(), time.process_time()
        scene.frame_set(frame)
        path = Path(path)
        tmp = path.with_name(f".{path.stem}.tmp.png")
        scene.render.filepath = str(tmp)
        bpy.ops.render.render(write_still=True)
        os.replace(tmp, path)
        print(f"{FRAME_LINE} {frame} {time.perf_counter() - t0:.3f} {time.process_time() - c0:.3f}", flush=True)


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python -m mpmfx.render.cycles_job JOB.json", file=sys.stderr)
        return 2
    job = json.loads(Path(argv[0]).read_text())
    build_scene(job)
    scene = bpy.context.scene
    scene.frame_set(job["frames"][0])
    if job.get("blend"):
        blend = Path(job["blend"])
        blend.parent.mkdir(parents=True, exist_ok=True)
        tmp = blend.with_name(f".{blend.stem}.tmp.blend")
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp), copy=True, compress=True)
        os.replace(tmp, blend)
    render_frames(job)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
