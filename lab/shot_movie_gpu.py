"""A production shot end to end on the GPU (`mpmfx bench shot`'s measure), then its frames'
surfaces brought back for a Cycles movie here (the GPU machine has no Blender).

    python lab/shot_movie_gpu.py run [--grid 400 --frames 96]      # warm-up, then the shot: table
    python lab/shot_movie_gpu.py proxies [--voxel-h 2]            # every frame, packed into $OUT

`run`: a small warm-up of the same shot compiles Warp's kernels (timed alone), then hero_castle at
grid 400 (10.1M Granular particles, dx 5 mm) for 96 frames runs voxelise, simulate, surface and
export with the stages overlapped, in /tmp/shot_cache; prints `mpmfx bench shot`'s table and
writes shot.json to $OUT. `proxies`: each cached frame's particles surfaced again at a coarser
voxel (2 particle spacings: ~16x fewer faces than the shot's own surface, ~1.6 px of a 480-px
movie) and packed with hero_codec into at most 8 tar files of < 16 MiB, with a hero_times.json
that `python lab/hero_render.py RETURNED --frames ...` reads to export and render them here.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import tarfile
import time
from pathlib import Path

import hero_codec

SHOT = Path(__file__).parents[1] / "pipeline" / "shots" / "hero_castle.toml"
CACHE = Path("/tmp/shot_cache")
PART_BYTES = 15 * 2**20  # a returned file's cap is 16 MiB
MAX_PARTS = 8


def overrides(grid: int, frames: int, extra=()) -> list[str]:
    """The shot at `grid` (its floor kept at y = 0), `frames` long; `extra` --set overrides."""
    dx = 2.0 / grid
    return [f"domain.grid_n={grid}", f"domain.origin=[-1.0, {-3 * dx:.6g}, -1.0]", f"shot.frame_end={frames}", *extra]


def run(args) -> None:
    from mpmfx.bench.shot import measure, table

    out = Path(os.environ.get("OUT", "shot_out"))
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    measure(SHOT, overrides=overrides(48, 3, args.overrides), cache=CACHE / "warmup", device=args.device)
    print(f"warm-up (kernel compiles, grid 48, 3 frames): {time.perf_counter() - t0:.1f} s", flush=True)
    row = measure(SHOT, overrides=overrides(args.grid, args.frames, args.overrides), cache=CACHE, device=args.device)
    print(table(row), flush=True)
    (out / "shot.json").write_text(json.dumps(row, indent=1))


def proxies(args) -> None:
    import warp as wp

    wp.config.quiet = True
    import mpmfx
    from mpmfx.io.frames import ParticleFrame
    from mpmfx.stages.surface import surface_params
    from mpmfx.surface import surface_particles

    out = Path(os.environ.get("OUT", "shot_out"))
    work = Path("/tmp/shot_proxies")
    work.mkdir(parents=True, exist_ok=True)
    over = overrides(args.grid, args.frames, args.overrides)
    shot_run = mpmfx.load_shot(SHOT, overrides=over, cache_root=CACHE, device=args.device, quiet=True)
    sim = shot_run.entries()["simulate"]
    (group,) = set(shot_run.shot.surface_groups())  # one object: one surface group
    params = dataclasses.replace(
        surface_params(shot_run.shot, group),
        voxel_size=args.voxel_h * shot_run.shot.particle_spacing,
        density=False,
    )
    t0, packed, faces = time.perf_counter(), [], 0
    for f in sim.done_frames("npz"):
        p = sim.read(sim.frame_path(f, "npz"), ParticleFrame.read)
        res = surface_particles(p.x, p.v, params, device=args.device)
        m = res.mesh
        faces += len(m.faces)
        mesh = {"vertices": m.vertices, "faces": m.faces, "velocities": m.velocities, "voxel": params.voxel_size}
        hero_codec.write(work / f"hero_castle_{f:04d}.hm", {group: mesh}, preset=6, part_bytes=2**40)
        packed.append({"frame": f, "faces": len(m.faces)})
    print(
        f"proxies: {len(packed)} frames, {faces / max(len(packed), 1):,.0f} faces a frame, "
        f"{time.perf_counter() - t0:.1f} s",
        flush=True,
    )
    info = {
        "device": __import__("mpmfx.bench.shots", fromlist=["x"]).device_name(args.device),
        "shots": [
            {
                "shot": "hero_castle",
                "overrides": over + [f"surface.voxel_size={params.voxel_size}"],
                "packed": packed,
                "stages": {"surface": {"seconds": 0.0}},
                "voxel_m": params.voxel_size,
            }
        ],
    }
    (work / "hero_times.json").write_text(json.dumps(info, indent=1))
    files = sorted(work.glob("*.hm")) + [work / "hero_times.json"]
    part, size, n = None, 0, 0
    for path in files:
        if part is None or size + path.stat().st_size > PART_BYTES:
            if part:
                part.close()
            part, size = tarfile.open(out / f"movie_{n:02d}.tar", "w"), 0
            n += 1
            assert n <= MAX_PARTS, "the proxies do not fit the returned files: raise --voxel-h"
        part.add(path, arcname=path.name)
        size += path.stat().st_size + 1024
    part.close()
    print(f"packed into {n} files, {sum(p.stat().st_size for p in out.glob('movie_*.tar')) / 2**20:.1f} MiB")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=("run", "proxies"))
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--grid", type=int, default=400)
    ap.add_argument("--frames", type=int, default=96)
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="more shot overrides")
    ap.add_argument("--voxel-h", type=float, default=2.0, help="proxies: the voxel in particle spacings")
    args = ap.parse_args(argv)
    (run if args.what == "run" else proxies)(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
