"""Run the GPU hero shots (pipeline/shots/hero_*.toml) through voxelise, simulate and surface with the
product's own stage runner (`mpmfx.load_shot(...).run(until="surface", frames=...)`, the path of
`mpmfx run SHOT --until surface --frames ...`), time every stage, and pack the still frames'
surfaces for the trip back (scripts/hero_codec.py: lossy-compact meshes, split under 15 MiB).

    python3 scripts/hero_gpu.py                      # on the GPU: both hero shots, outputs to $OUT
    python3 scripts/hero_gpu.py --smoke --device cpu # CPU size (grid 32, few frames): tests the path
    python3 scripts/hero_gpu.py --no-pack            # the stage times only (no surfaces brought back)

Imports numpy, warp and mpmfx only (and what the stages import: pydantic, tqdm, trimesh). Writes
$OUT/hero_times.json (per shot: particles, grid, frames, substeps, seconds per stage, mesh sizes,
the device) and $OUT/<shot>_<frame>.hm[.NNN]; prints one table at the end.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(Path(__file__).resolve().parent)]

import hero_codec  # noqa: E402  (scripts/, beside this file)

# shot -> frames to surface and bring back, best first (hero_render.py's README_STILL picks the README's).
SHOTS = {"hero_dam": [8, 6], "hero_castle": [7, 12]}
RETURN_BYTES = 58 * 2**20   # of the 64 MiB the device tool brings back; the JSON and log need little
RETURN_FILES = 7            # of its 8 files: one is hero_times.json


def smoke_overrides(grid_n: int, last: int) -> list[str]:
    """CPU size: a coarse grid (domain origin kept 3 cells below y = 0, the solver's floor) and a
    short shot; everything else is the shot's own."""
    dx = 2.0 / grid_n
    return [f"domain.grid_n={grid_n}", f"domain.origin=[-1.0, {-3 * dx}, -1.0]", f"shot.frame_end={last}"]


def run_shot(name: str, frames: list[int], *, overrides: list[str], cache: Path, device: str) -> dict:
    import mpmfx
    shot_file = ROOT / "pipeline" / "shots" / f"{name}.toml"
    run = mpmfx.load_shot(shot_file, overrides=overrides, cache_root=cache, device=device, quiet=True, workers=1)
    t0 = time.perf_counter()
    results = run.run(until="surface", frames=frames)
    wall = time.perf_counter() - t0
    entries = run.entries()
    man = {s: entries[s].manifest() or {} for s in ("voxelise", "simulate", "surface")}
    qa = man["simulate"].get("qa", {})
    substeps = [int(q.get("substeps", 0)) for f, q in sorted(qa.items(), key=lambda kv: int(kv[0])) if int(f) > run.shot.shot.frame_start]
    return {
        "shot": name, "overrides": overrides, "grid_n": run.shot.domain.grid_n, "domain_m": run.shot.domain.size,
        "frames_simulated": len(man["simulate"].get("frames", [])),
        "seconds_of_shot": (len(man["simulate"].get("frames", [1])) - 1) / run.shot.shot.fps,
        "frames_surfaced": frames, "particles": man["voxelise"].get("particles"),
        "substeps_total": sum(substeps), "substeps_per_frame": [min(substeps or [0]), max(substeps or [0])],
        "stages": {r.stage: {"seconds": round(r.seconds, 2), "state": r.state, "frames": r.frames} for r in results},
        "simulate_split": man["simulate"].get("seconds_split"),
        "run_wall_s": round(wall, 2), "surface_vertices": man["surface"].get("this_run", {}).get("vertices"),
        "surface_faces": man["surface"].get("this_run", {}).get("faces"),
        "voxel_m": None, "_surface_entry": str(entries["surface"].root), "_shot": run.shot,
    }


def pack_frame(row: dict, frame: int, out: Path, *, budget: dict) -> dict:
    """Encode one surfaced frame into out/<shot>_<frame>.hm (split if large), within budget."""
    from mpmfx.io.frames import SurfaceFrame
    surf = SurfaceFrame.read(Path(row["_surface_entry"]) / "frames" / f"{frame:04d}.npz")
    groups = {g: {"vertices": d.vertices, "faces": d.faces, "velocities": d.velocities, "voxel": float(d.voxel_size)}
              for g, d in surf.groups.items()}
    row["voxel_m"] = float(next(iter(surf.groups.values())).voxel_size) if surf.groups else None
    meta = {"shot": row["shot"], "frame": frame, "overrides": row["overrides"],
            "vertices": {g: len(d.vertices) for g, d in surf.groups.items()},
            "faces": {g: len(d.faces) for g, d in surf.groups.items()}}
    t0 = time.perf_counter()
    tmp = out / ".pack"
    tmp.mkdir(exist_ok=True)
    files = hero_codec.write(tmp / f"{row['shot']}_{frame:04d}.hm", groups, meta)
    size = sum(f.stat().st_size for f in files)
    info = {"frame": frame, "bytes": size, "files": [f.name for f in files], "encode_s": round(time.perf_counter() - t0, 2),
            **{k: meta[k] for k in ("vertices", "faces")}}
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


def device_name(device: str) -> str:
    import warp as wp
    d = wp.get_device(device)
    return getattr(d, "name", str(d)) if d.is_cuda else f"CPU ({platform.processor() or platform.machine()}, {os.cpu_count()} cores)"


def table(rows: list[dict], warm: dict | None, dev: str) -> str:
    lines = [f"device: {dev}"]
    if warm:
        lines.append(f"warm-up (Warp kernel compiles, {warm['shot']} at grid {warm['grid_n']}): "
                     f"{warm['run_wall_s']} s")
    head = ("shot", "particles", "grid", "frames", "substeps", "voxelise s", "simulate s", "surface s",
            "surf frames", "vertices", "packed MiB")
    lines.append(" | ".join(head))
    for r in rows:
        st = r["stages"]
        packed = sum(p["bytes"] for p in r.get("packed", []) if "skipped" not in p) / 2**20
        lines.append(" | ".join(str(x) for x in (
            r["shot"], r["particles"], r["grid_n"], r["frames_simulated"], r["substeps_total"],
            st.get("voxelise", {}).get("seconds"), st.get("simulate", {}).get("seconds"),
            st.get("surface", {}).get("seconds"), len(r["frames_surfaced"]), r["surface_vertices"], f"{packed:.1f}")))
        if r.get("simulate_split"):
            lines.append(f"  {r['shot']} simulate, s: " + ", ".join(f"{k} {v}" for k, v in r["simulate_split"].items()))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--smoke", action="store_true", help="CPU size: grid 32, frames up to the second still only")
    ap.add_argument("--shots", nargs="*", default=list(SHOTS))
    ap.add_argument("--cache", default="/tmp/hero_cache")
    ap.add_argument("--out", default=os.environ.get("OUT", "hero_out"))
    ap.add_argument("--budget-s", type=float, default=330.0,
                    help="start no further shot after this many seconds (the device call's limit is 600 s)")
    ap.add_argument("--pack", action=argparse.BooleanOptionalAction, default=True,
                    help="bring the stills' surfaces back (off: times only)")
    ap.add_argument("--warmup", action=argparse.BooleanOptionalAction, default=None,
                    help="a small first run that compiles the kernels (default: on, off with --smoke)")
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
        # Compiling Warp's kernels (first use on a fresh machine) would otherwise land in the first
        # shot's stage times: a tiny run of the same stages compiles them, timed on its own.
        t0 = time.perf_counter()
        for name in args.shots:  # every shot: each material's and collider's kernels
            warm = run_shot(name, [3], overrides=smoke_overrides(32, 3), cache=cache / "warmup", device=args.device)
        warm["run_wall_s"] = round(time.perf_counter() - t0, 2)
        warm["shot"] = ", ".join(args.shots)
        print(f"warm-up done in {warm['run_wall_s']} s", flush=True)
    rows = []

    def save() -> None:  # after every shot: a run cut short still returns what it finished
        report = {"device": dev, "warp": wp.config.version, "python": platform.python_version(), "smoke": args.smoke,
                  "warmup": _public(warm) if warm else None, "shots": [_public(r) for r in rows],
                  "elapsed_s": round(time.perf_counter() - t_start, 1)}
        (out / "hero_times.json").write_text(json.dumps(report, indent=1))

    for name in args.shots:
        elapsed = time.perf_counter() - t_start
        if elapsed > args.budget_s:
            print(f"{name}: skipped, {elapsed:.0f} s used of the {args.budget_s} s budget", flush=True)
            continue
        frames = SHOTS[name]
        over = smoke_overrides(32, max(frames)) if args.smoke else []
        print(f"{name}: running voxelise, simulate, surface (frames {frames}) ...", flush=True)
        row = run_shot(name, frames, overrides=over, cache=cache, device=args.device)
        print(f"{name}: {row['stages']}", flush=True)
        rows.append(row)
        if args.pack:
            _pack_into(row, 0, out, budget)  # its README still at once
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
    print(f"packed {row['shot']} frame {info['frame']}: {info['bytes'] / 2**20:.1f} MiB in {info['encode_s']} s "
          f"{info.get('skipped', '')}", flush=True)


def _public(row: dict) -> dict:
    return {k: v for k, v in row.items() if not k.startswith("_")}


if __name__ == "__main__":
    sys.exit(main())
