"""Run the GPU hero shots as `mpmfx bench shots` does (mpmfx.bench.shots: voxelise, simulate and
surface through the stage runner, every stage timed) and pack the still frames' surfaces for the
trip back from a remote GPU machine (hero_codec.py: lossy-compact meshes, split under 15 MiB), to
be exported and rendered by hero_render.py.

    python lab/hero_gpu.py --out DIR                   # on the GPU: both hero shots
    python lab/hero_gpu.py --shots stomp water_pour    # example shots at production size (EXAMPLES)
    python lab/hero_gpu.py --smoke --device cpu        # CPU size (grid 32, few frames): tests the path

Imports numpy, warp and mpmfx only (and what the stages import: pydantic, tqdm, trimesh). Writes
DIR/hero_times.json (per shot: particles, grid, frames, substeps, seconds per stage, mesh sizes,
the device) and DIR/<shot>_<frame>.hm[.NNN], within a return budget of RETURN_BYTES in
RETURN_FILES files; prints one table at the end.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import hero_codec

from mpmfx.bench.shots import SHOT_DIR, SHOTS, SMOKE_GRID, device_name, public, run_shot, smoke_overrides, warm_up
from mpmfx.bench.shots import table as shots_table

EXAMPLES = {"stomp": (256, [34]), "tyre_mud": (256, [36]), "water_pour": (256, [24]), "sand_pour": (192, [60])}
"""Example shot -> (its production grid, the frames to surface): a grid four to five times the
CPU size's 48, the domain's floor kept 3 cells below y = 0 as the shots place it."""

RETURN_BYTES = 58 * 2**20  # what the packed frames may take of a 64 MiB return; the JSON and log need little
RETURN_FILES = 7  # of 8 returned files: one is hero_times.json


def pack_frame(row: dict, frame: int, out: Path, *, budget: dict) -> dict:
    """Encode one surfaced frame into out/<shot>_<frame>.hm (split if large), within budget."""
    from mpmfx.io.frames import SurfaceFrame

    surf = SurfaceFrame.read(Path(row["_surface_entry"]) / "frames" / f"{frame:04d}.npz")
    groups = {
        g: {"vertices": d.vertices, "faces": d.faces, "velocities": d.velocities, "voxel": float(d.voxel_size)}
        for g, d in surf.groups.items()
    }
    row["voxel_m"] = float(next(iter(surf.groups.values())).voxel_size) if surf.groups else None
    meta = {
        "shot": row["shot"],
        "frame": frame,
        "overrides": row["overrides"],
        "vertices": {g: len(d.vertices) for g, d in surf.groups.items()},
        "faces": {g: len(d.faces) for g, d in surf.groups.items()},
    }
    t0 = time.perf_counter()
    tmp = out / ".pack"
    tmp.mkdir(exist_ok=True)
    files = hero_codec.write(tmp / f"{row['shot']}_{frame:04d}.hm", groups, meta)
    size = sum(f.stat().st_size for f in files)
    info = {
        "frame": frame,
        "bytes": size,
        "files": [f.name for f in files],
        "encode_s": round(time.perf_counter() - t0, 2),
        **{k: meta[k] for k in ("vertices", "faces")},
    }
    if size > budget["bytes"] or len(files) > budget["files"]:
        info["skipped"] = f"over the return budget ({budget['bytes']} B, {budget['files']} files left)"
        for f in files:
            f.unlink()
        return info
    for f in files:
        f.replace(out / f.name)
    budget["bytes"] -= size
    budget["files"] -= len(files)
    return info


def production(name: str, grid: int | None = None) -> list[str]:
    """The overrides of an example shot at its production grid (or at `grid`)."""
    from mpmfx.shotfile import load_shot_config

    grid = grid or EXAMPLES[name][0]
    dom = load_shot_config(SHOT_DIR / f"{name}.toml").domain
    ox, _, oz = dom.origin
    return [f"domain.grid_n={grid}", f"domain.origin=[{ox}, {-3 * dom.size / grid}, {oz}]"]


def table(rows: list[dict], warm: dict | None, dev: str) -> str:
    """`mpmfx bench shots`'s table, and the MiB packed per shot."""
    packed = [
        f"{r['shot']} packed: {sum(p['bytes'] for p in r.get('packed', []) if 'skipped' not in p) / 2**20:.1f} MiB"
        for r in rows
    ]
    return "\n".join([shots_table(rows, warm, dev), *packed])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--smoke", action="store_true", help="CPU size: grid 32, frames up to the second still only")
    ap.add_argument("--shots", nargs="*", default=list(SHOTS))
    ap.add_argument("--cache", default="/tmp/hero_cache")
    ap.add_argument("--out", default=os.environ.get("OUT", "hero_out"))
    ap.add_argument(
        "--budget-s",
        type=float,
        default=330.0,
        help="start no further shot after this many seconds (a remote call's time limit)",
    )
    ap.add_argument(
        "--pack",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="bring the stills' surfaces back (off: times only)",
    )
    ap.add_argument(
        "--warmup",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="a small first run that compiles the kernels (default: on, off with --smoke)",
    )
    args = ap.parse_args(argv)
    out, cache = Path(args.out), Path(args.cache)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    import warp as wp

    wp.config.quiet = True
    dev = device_name(args.device)
    print(f"hero_gpu: {dev}, warp {wp.config.version}, numpy {__import__('numpy').__version__}", flush=True)
    budget = {"bytes": RETURN_BYTES, "files": RETURN_FILES}
    warm = None
    if args.warmup if args.warmup is not None else not args.smoke:
        warm = warm_up(args.shots, cache / "warmup", args.device)
        print(f"warm-up done in {warm['run_wall_s']} s", flush=True)
    rows = []

    def save() -> None:  # after every shot: a run cut short still returns what it finished
        report = {
            "device": dev,
            "warp": wp.config.version,
            "python": platform.python_version(),
            "smoke": args.smoke,
            "warmup": public(warm) if warm else None,
            "shots": [public(r) for r in rows],
            "elapsed_s": round(time.perf_counter() - t_start, 1),
        }
        (out / "hero_times.json").write_text(json.dumps(report, indent=1))

    for name in args.shots:
        elapsed = time.perf_counter() - t_start
        if elapsed > args.budget_s:
            print(f"{name}: skipped, {elapsed:.0f} s used of the {args.budget_s} s budget", flush=True)
            continue
        frames = SHOTS[name] if name in SHOTS else EXAMPLES[name][1]
        if name in EXAMPLES:
            over = production(name, SMOKE_GRID if args.smoke else None)
        else:
            over = smoke_overrides(SMOKE_GRID, max(frames)) if args.smoke else []
        print(f"{name}: running voxelise, simulate, surface (frames {frames}) ...", flush=True)
        row = run_shot(name, frames, overrides=over, cache=cache, device=args.device)
        print(f"{name}: {row['stages']}", flush=True)
        rows.append(row)
        if args.pack:
            _pack_into(row, 0, out, budget)  # its first still at once
        save()
    for row in rows if args.pack else ():  # then the second frames, while the return budget lasts
        for rank in range(1, len(row["frames_surfaced"])):
            _pack_into(row, rank, out, budget)
    pack_dir = out / ".pack"
    if pack_dir.exists() and not any(pack_dir.iterdir()):
        pack_dir.rmdir()
    save()
    print(table(rows, warm, dev), flush=True)
    return 0


def _pack_into(row: dict, rank: int, out: Path, budget: dict) -> None:
    info = pack_frame(row, row["frames_surfaced"][rank], out, budget=budget)
    row.setdefault("packed", []).append(info)
    print(
        f"packed {row['shot']} frame {info['frame']}: {info['bytes'] / 2**20:.1f} MiB in {info['encode_s']} s "
        f"{info.get('skipped', '')}",
        flush=True,
    )


if __name__ == "__main__":
    sys.exit(main())
