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
import os
import sys
import time
from pathlib import Path

import bpy

from mpmfx.blender import FRAME_LINE, NOTE_LINE, die_with_parent, temp_name
from mpmfx.render import blender_scene as bs
from mpmfx.render.blender_scene import assign, make_material
from mpmfx.render.label import burn_label
from mpmfx.render.looks import GROUND_FADE, GROUND_MIN, GROUND_SPAN, WORLD, metres_per_pixel


def import_stage(usd: str) -> dict[str, list]:
    """Import the USD stage and sort what came in: {"meshes", "points", "volumes", "colliders",
    "cameras"} -> [(prim name, object)], by the scope each prim sits in (`mpmfx.io.usd`: /World/
    surfaces, particles, volumes, colliders). Hidden prims (particles, level sets) come in too."""
    res = bpy.ops.wm.usd_import(
        filepath=usd,
        set_frame_range=True,
        merge_parent_xform=False,
        import_lights=False,
        import_materials=False,
        import_visible_only=False,
        relative_path=False,
        create_world_material=False,
    )
    if res != {"FINISHED"}:
        raise RuntimeError(f"{usd}: Blender's USD importer did not finish ({res})")
    out: dict[str, list] = {k: [] for k in ("meshes", "points", "volumes", "colliders", "cameras")}
    kinds = {"surfaces": "meshes", "particles": "points", "volumes": "volumes", "colliders": "colliders"}
    for obj in bpy.data.objects:
        scope = _prim_name(obj.parent) if obj.parent else ""
        if obj.type == "CAMERA":
            out["cameras"].append((_prim_name(obj), obj))
        elif scope in kinds and obj.type in ("MESH", "POINTCLOUD", "VOLUME"):
            out[kinds[scope]].append((_prim_name(obj), obj))
    return out


def _prim_name(obj) -> str:
    """The USD prim name of an imported object: Blender appends .001 to repeated names."""
    head, dot, tail = obj.name.rpartition(".")
    return head if dot and tail.isdigit() else obj.name


def set_looks(job: dict, imported: dict) -> None:
    """Materials per look; surface mode shows the meshes, particles mode the points; volumes
    (the .vdb level sets) stay in the file for the artist but out of the picture. Glints are
    sized in pixels of this render (its width, the camera's distance to what it looks at)."""
    made: dict[str, object] = {}
    pixel_m = metres_per_pixel(job["camera"], job["width"])

    def material(look):
        if look not in made:
            made[look] = make_material(look, look, pixel_m)
        return made[look]

    particles = job["mode"] == "particles"
    for kind, show in (("meshes", not particles), ("points", particles)):
        for name, obj in imported[kind]:
            obj.hide_render = not show
            if show:
                assign(obj, material(job["looks"].get(name, "plastic")))
    for _, obj in imported["volumes"]:
        obj.hide_render = True
    for name, obj in imported["colliders"]:  # (a glass the material pours into: render.looks names it)
        assign(obj, material(job.get("collider_looks", {}).get(name, "collider")))


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
    if job.get("threads"):  # a worker's share of the cores (several Blenders on one host)
        r.threads_mode, r.threads = "FIXED", int(job["threads"])
    r.use_persistent_data = True  # shaders and the unchanged scene stay compiled between frames
    r.image_settings.file_format, r.image_settings.color_mode = "PNG", "RGB"
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.look = "AgX - Medium High Contrast"
    r.use_stamp = False  # a variant's label is burned in after the render (`burn_label`)


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
    cam = job["camera"]  # the exported USD's camera (`mpmfx.render.camera.render_camera`)
    scene.camera = bs.add_camera(
        cam["position"], cam["look_at"], focal_mm=cam["focal_length"], film_mm=cam["horizontal_aperture"]
    )
    set_render(job)


def render_frames(job: dict) -> None:
    """Render each frame to its PNG (written to a temp name, then renamed: complete or absent)."""
    scene = bpy.context.scene
    for frame, path in zip(job["frames"], job["outputs"]):
        t0, c0 = time.perf_counter(), time.process_time()
        scene.frame_set(frame)
        path = Path(path)
        tmp = temp_name(path)
        scene.render.filepath = str(tmp)
        bpy.ops.render.render(write_still=True)
        if job.get("label"):  # a variant (--set) says which one it is, and the frame, on every frame
            burn_label(tmp, f"{job['label']}  frame {frame}")
        os.replace(tmp, path)
        print(f"{FRAME_LINE} {frame} {time.perf_counter() - t0:.3f} {time.process_time() - c0:.3f}", flush=True)


def save_blend(job: dict) -> None:
    """Save the lit scene as job["blend"], its USD and VDB paths pointing where the hand-off
    lands: every file of the export entry (job["usd"]'s folder) by `job["blend_usd_root"]`, a
    Blender path relative to the .blend's published folder (`//../../published/<name>`), so the
    .blend plays from renders/<name>/ and still does when the project folder moves. Call it
    after the frames: a relative path does not resolve before the scene is saved."""
    export_root = str(Path(job["usd"]).parent)
    new_root = job.get("blend_usd_root")
    if new_root:
        for block in [*bpy.data.cache_files, *bpy.data.volumes]:
            path = bpy.path.abspath(block.filepath)
            if path == export_root or path.startswith(export_root + os.sep):
                rel = Path(os.path.relpath(path, export_root)).as_posix()
                block.filepath = new_root if rel == "." else f"{new_root}/{rel}"
    bpy.context.scene.frame_set(job["frames"][0])
    blend = Path(job["blend"])
    blend.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_name(blend)
    # relative_remap off: the paths stay as set above, not rewritten against the temp's folder
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp), copy=True, compress=True, relative_remap=False)
    os.replace(tmp, blend)


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python -m mpmfx.render.cycles_job JOB.json", file=sys.stderr)
        return 2
    die_with_parent()
    job = json.loads(Path(argv[0]).read_text())
    build_scene(job)
    render_frames(job)
    if job.get("blend"):
        save_blend(job)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
