"""Where a shot's simulate time goes: per frame wall time through `Solver.advance` (the path a
shot runs), then one frame with every kernel timed (CUDA graphs off), summed by kernel name.

    python lab/shot_profile.py hero_dam hero_castle --frames 3 --out DIR   # on the GPU
    python lab/shot_profile.py hero_dam --smoke --device cpu              # CPU size

Builds the solver exactly as the simulate stage does (stages.simulate.materials / colliders /
the voxelise stage's seeds). Prints one table per shot and writes DIR/shot_profile.json.
Imports numpy, warp and mpmfx (and what loading a shot imports: pydantic, trimesh).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from mpmfx.bench.shots import SHOT_DIR, device_name, smoke_overrides


def build(name: str, overrides: list[str], cache: Path, device: str):
    """(solver, state, shot) at the shot's first frame, seeded as the simulate stage seeds."""
    import mpmfx
    from mpmfx.io.frames import SeedParticles
    from mpmfx.mpm import Particles, Solver
    from mpmfx.stages import simulate

    run = mpmfx.load_shot(
        SHOT_DIR / f"{name}.toml", overrides=overrides, cache_root=cache, device=device, quiet=True, workers=1
    )
    run.run(until="voxelise")
    shot = run.shot
    origin, size = np.asarray(shot.domain.origin), shot.domain.size
    mats, obj_mat = simulate.materials(shot)
    solver = Solver(mats, shot.solver_config(), colliders=simulate.colliders(shot), device=device)
    p = SeedParticles.read(run.entries()["voxelise"].root)
    body = p.body.astype(np.int32)
    parts = Particles(
        x=((p.x - origin) / size).astype(np.float32),
        v=(p.v / size).astype(np.float32),
        volume=(p.volume / size**3).astype(np.float32),
        material=np.asarray(obj_mat, np.int32)[body],
        body=body,
    )
    return solver, solver.init_state(parts), shot


def kernel_split(solver, state, t0: float, t1: float) -> tuple[dict, object]:
    """Device ms summed per kernel name over one advance with the kernels launched one by one."""
    import warp as wp

    da = solver._device_advance
    graphs, da.graphs = da.graphs, False
    wp.timing_begin(cuda_filter=wp.TIMING_KERNEL | wp.TIMING_MEMSET | wp.TIMING_MEMCPY)
    report = solver.advance(state, t0, t1)
    results = wp.timing_end()
    da.graphs = graphs
    ms: dict[str, float] = {}
    for r in results:
        key = r.name.split("_cuda_kernel")[0]
        ms[key] = ms.get(key, 0.0) + r.elapsed
    return ms, report


def profile(name: str, frames: int, overrides: list[str], cache: Path, device: str) -> dict:
    import warp as wp

    from mpmfx.stages.simulate import _host

    t0 = time.perf_counter()
    solver, state, shot = build(name, overrides, cache, device)
    setup = time.perf_counter() - t0
    fps, start = shot.shot.fps, shot.shot.frame_start
    rows = []
    for f in range(1, frames + 1):  # frame 1 compiles and captures
        wp.synchronize_device(solver.device)
        t0 = time.perf_counter()
        rep = solver.advance(state, (f - 1) / fps, f / fps)
        wp.synchronize_device(solver.device)
        wall = time.perf_counter() - t0
        t0 = time.perf_counter()
        _host(solver, state, {})  # the frame file's host copy (its constant arrays left out)
        copy = time.perf_counter() - t0
        k = rep.substeps + rep.rejected_substeps
        rows.append(
            {
                "frame": start + f,
                "substeps": rep.substeps,
                "rejected": rep.rejected_substeps,
                "wall_s": wall,
                "ms_substep": 1e3 * wall / max(1, k),
                "host_copy_s": copy,
                "G_per_s": state.n * rep.substeps / wall / 1e9,
                "sort_every": state.clock.sort_every,
            }
        )
        print(
            f"{name} frame {start + f}: {rep.substeps} substeps (+{rep.rejected_substeps} rejected), "
            f"{wall:.2f} s, {1e3 * wall / max(1, k):.3f} ms/substep, host copy {copy:.3f} s, "
            f"sorting every {state.clock.sort_every}",
            flush=True,
        )
    split = {}
    if solver.device.is_cuda:
        f = frames + 1
        t0 = time.perf_counter()
        ms, rep = kernel_split(solver, state, (f - 1) / fps, f / fps)
        wall = time.perf_counter() - t0
        k = max(1, rep.substeps + rep.rejected_substeps)
        split = {
            "substeps": k,
            "wall_ms_substep_nograph": 1e3 * wall / k,
            "kernels_ms_substep": {n: v / k for n, v in sorted(ms.items(), key=lambda kv: -kv[1])},
        }
    cfg = solver.config
    return {
        "shot": name,
        "particles": int(state.n),
        "grid_n": cfg.grid_n,
        "p2g": solver._device_advance.p2g,
        "deterministic": cfg.deterministic,
        "colliders": len(solver.colliders),
        "setup_s": setup,
        "frames": rows,
        "split": split,
    }


def table(r: dict) -> str:
    steady = r["frames"][1:] or r["frames"]
    ms = float(np.mean([f["ms_substep"] for f in steady]))
    gps = float(np.mean([f["G_per_s"] for f in steady]))
    lines = [
        f"{r['shot']}: {r['particles']} particles, grid {r['grid_n']}, P2G {r['p2g']}, "
        f"steady {ms:.3f} ms/substep = {gps:.2f} G/s (frames 2..)"
    ]
    sp = r["split"]
    if sp:
        tot = sum(sp["kernels_ms_substep"].values())
        lines.append(f"  no graphs: {sp['wall_ms_substep_nograph']:.3f} ms/substep wall, kernels {tot:.3f} ms")
        for n, v in list(sp["kernels_ms_substep"].items())[:14]:
            lines.append(f"    {v:8.3f} ms  {n}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("shots", nargs="*", default=["hero_dam", "hero_castle"])
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--smoke", action="store_true", help="grid 32 (CPU size)")
    ap.add_argument("--set", action="append", default=[], help="extra shot overrides key=value")
    ap.add_argument("--cache", default="/tmp/profile_cache")
    ap.add_argument("--out", default=os.environ.get("OUT", "profile_out"))
    args = ap.parse_args(argv)
    import warp as wp

    wp.config.quiet = True
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = []
    for name in args.shots:
        ov = (smoke_overrides(32, args.frames + 3) if args.smoke else []) + args.set
        results.append(profile(name, args.frames, ov, Path(args.cache), args.device))
        (out / "shot_profile.json").write_text(
            json.dumps({"device": device_name(args.device), "shots": results}, indent=1)
        )
    print(f"device: {device_name(args.device)}, warp {wp.config.version}")
    for r in results:
        print(table(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
