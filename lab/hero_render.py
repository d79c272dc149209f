"""Render the README stills of the GPU hero shots from the surfaces hero_gpu.py brought back.

    python lab/hero_render.py RETURNED_DIR [--cache DIR] [--shots ...] [--frames ...]

RETURNED_DIR holds hero_times.json and <shot>_<frame>.hm[.NNN] (hero_codec.py). For each shot:
the decoded meshes become that frame's surface stage frame in a local cache (the shot's own cache
key; the level set leaves do not travel, so the export writes no VDBs), then the product's export
and render stages run on those frames exactly as `mpmfx run` runs them (USD stage, Blender's USD
import, Cycles with the shot's [render] settings), and the README still (the first still, or
README_STILL) is copied to docs/images/<shot>.png. Prints the CPU times of export and render.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import hero_codec

from mpmfx.bench.shots import SHOT_DIR

# The README still of a shot, where it is not the first still brought back: by hero_dam's frame 8
# its sheets have reached the domain's side walls (straight cut edges, water climbing air).
README_STILL = {"hero_dam": 6}


def import_frames(run, returned: Path, frames: list[int], info: dict) -> list[int]:
    """Write the decoded meshes as surface stage frames of `run`'s cache and its manifest."""
    from mpmfx.io.frames import GroupSurface, SurfaceFrame

    entry = run.entries()["surface"]
    done = []
    for f in frames:
        groups, meta = hero_codec.read(returned / f"{run.shot.shot.name}_{f:04d}.hm")
        voxel = info.get("voxel_m") or 0.0
        out = {
            g: GroupSurface(
                vertices=v,
                faces=fc,
                normals=n,
                velocities=vel,
                voxel_size=voxel,
                background=3 * voxel,
            )
            for g, (v, fc, n, vel) in groups.items()
        }
        SurfaceFrame(out).write(entry.frame_path(f, SurfaceFrame.EXT))
        done.append(f)
        print(f"{run.shot.shot.name} frame {f}: " + ", ".join(f"{g} {len(v[0]):,} vertices" for g, v in groups.items()))
    entry.write_manifest(
        frames=entry.done_frames(SurfaceFrame.EXT),
        timings={"gpu_surface_s": info["stages"]["surface"]["seconds"]},
        extra={
            "imported": f"decoded from {returned} (lab/hero_codec.py, lossy: vertices to 1/32 voxel, "
            f"velocities int8); surfaced on {info.get('device', '?')}",
            "this_run": {"vertices": info.get("surface_vertices"), "faces": info.get("surface_faces")},
        },
    )
    return done


def run_stage(run, name: str, frames: list[int]) -> float:
    """One stage through the runner's own begin / run / end (cached: 0 s)."""
    from mpmfx.stages.runner import StageResult, stage_module

    with run.cache.lock():
        ctx = run.begin(name, run.entries(), frames)
        if isinstance(ctx, StageResult):
            return 0.0
        t0 = time.perf_counter()
        with run.failing(ctx):
            extra = stage_module(name).run(ctx) or {}
        secs = time.perf_counter() - t0
        run.end(ctx, extra, secs)
    return secs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("returned", type=Path)
    ap.add_argument("--cache", default="cache")
    ap.add_argument("--shots", nargs="*", default=None)
    ap.add_argument("--frames", nargs="*", type=int, default=None, help="frames to render (default: the README still)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="extra overrides (render.* only)")
    ap.add_argument("--readme", default="docs/images", help="folder the README stills are copied to")
    ap.add_argument("--suffix", default="", help="appended to the still's name: docs/images/<shot><suffix>.png")
    args = ap.parse_args(argv)
    import mpmfx
    from mpmfx.config import Export

    report = json.loads((args.returned / "hero_times.json").read_text())
    for info in report["shots"]:
        name = info["shot"]
        if args.shots and name not in args.shots:
            continue
        info["device"] = report["device"]
        packed = [p["frame"] for p in info.get("packed", []) if "skipped" not in p]
        want = args.frames or [README_STILL.get(name, packed[0])]
        frames = [f for f in want if f in packed]
        if not frames:
            print(f"{name}: none of frames {want} came back (have {packed}): skipped")
            continue
        run = mpmfx.load_shot(
            SHOT_DIR / f"{name}.toml", overrides=info["overrides"] + args.overrides, cache_root=args.cache, workers=1
        )
        # no level set leaves came back: the USD gets the meshes, not the .vdb files
        run.shot = run.shot.model_copy(update={"export": Export(vdb=False, points=False)})
        import_frames(run, args.returned, packed, info)
        t_exp = run_stage(run, "export", frames)
        t_ren = run_stage(run, "render", frames)
        png = run.entries()["render"].frame_path(frames[0], "png")
        dst = Path(args.readme) / f"{name}{args.suffix}.png"
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(png, dst)
        secs = (run.entries()["render"].manifest() or {}).get("cycles_seconds", {})
        print(
            f"{name}: frames {frames}: export {t_exp:.1f} s, render {t_ren:.1f} s (Cycles wall/CPU per frame: {secs}) "
            f"-> {dst}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
