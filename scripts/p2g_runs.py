"""The brick P2G in shots, both modes, variant against variant: how often it re-sorts its
particles (at chunk starts only, every k substeps, or as the order wears: p2g_brick.sort_cadence,
capped by travel_cadence at a SORT_TRAVEL); then the bench blocks. (The figures in p2g_brick's docstrings came from this
script with variants measured and then removed: warp runs, and float / int64 windows.)

    python3 scripts/p2g_runs.py hero_dam hero_castle --out $OUT     # on the GPU

Per shot: three frames to warm up, a checkpoint, then per variant: restore, one frame to
capture, one frame timed through advance() (CUDA graphs, as a shot runs), one frame with
every kernel timed (scatter and sort ms a substep). Writes $OUT/p2g_runs.json.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path[:0] = [str(Path(__file__).resolve().parents[1]), str(Path(__file__).resolve().parent)]
from hero_gpu import smoke_overrides  # noqa: E402
from shot_profile import build, kernel_split  # noqa: E402

VARIANTS = [(1.0, 32), (1.0, 0)]  # (SORT_TRAVEL, sort_every): 0 is sort_cadence


def shot_rows(name: str, cache: Path, device: str, overrides: list[str]) -> list[dict]:
    rows = []
    for det in ("true", "false"):
        rows += shot_variants(name, cache, device, [*overrides, f"solver.deterministic={det}"])
    return rows


def shot_variants(name: str, cache: Path, device: str, overrides: list[str]) -> list[dict]:
    import warp as wp
    from mpmfx.mpm import p2g_brick
    solver, state, shot = build(name, overrides, cache, device)
    fps = shot.shot.fps
    for f in range(1, 4):
        solver.advance(state, (f - 1) / fps, f / fps)
    ck = solver.checkpoint(state, 3 / fps)
    da, rows = solver._device_advance, []
    for travel, every in VARIANTS:
        p2g_brick.SORT_TRAVEL = travel
        da.sort_every = every
        da._brick = None
        st, t = solver.restore(ck)
        solver.advance(st, t, t + 1 / fps)
        wp.synchronize_device(solver.device)
        t0 = time.perf_counter()
        rep = solver.advance(st, t + 1 / fps, t + 2 / fps)
        wp.synchronize_device(solver.device)
        wall = time.perf_counter() - t0
        k = rep.substeps + rep.rejected_substeps
        ms, rep2 = kernel_split(solver, st, t + 2 / fps, t + 3 / fps)
        k2 = rep2.substeps + rep2.rejected_substeps
        scatter = sum(v for n, v in ms.items() if "scatter" in n) / k2
        sort = sum(v for n, v in ms.items() if "radix" in n or "scan" in n or "_seg_" in n or "_brick_keys" in n) / k2
        dt = 1 / fps / max(1, rep.substeps)
        cells = rep.max_speed * dt / solver.config.dx
        row = {"shot": name, "sort_every": every or f"travel {travel}", "cells_a_substep": cells,
               "travel_cap_now": p2g_brick.travel_cadence(rep.max_speed, dt, solver.config.dx, 32),
               "cadence_now": st.clock.sort_every,
               "particles": st.n, "substeps": rep.substeps,
               "ms_substep": 1e3 * wall / k, "G_per_s": st.n * rep.substeps / wall / 1e9, "ms_scatter": scatter,
               "ms_sort": sort, "deterministic": solver.config.deterministic}
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def bench_rows(device: str) -> list[dict]:
    from mpmfx.bench import gpu
    copy = gpu.copy_bandwidth(device)
    rows = []
    for grid_n in (128, 256):
        for scene in ("Water", "Mushy"):
            for det in (False, True):
                r = gpu.safe_case(scene, grid_n, det, device, copy)
                rows.append(r)
                print(json.dumps({k: r.get(k) for k in ("scene", "grid_n", "det", "G_per_s", "ms_substep", "ms_p2g",
                                                         "error")}), flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("shots", nargs="*", default=["hero_dam", "hero_castle"])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--no-bench", action="store_true")
    ap.add_argument("--smoke", action="store_true", help="grid 32, the first variant only (CPU size)")
    ap.add_argument("--cache", default="/tmp/profile_cache")
    ap.add_argument("--out", default=os.environ.get("OUT", "profile_out"))
    args = ap.parse_args(argv)
    import warp as wp
    wp.config.quiet = True
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res = {"device": wp.get_device(args.device).name, "shots": [], "bench": []}
    for name in args.shots:
        if args.smoke:
            VARIANTS[1:] = []
        res["shots"] += shot_rows(name, Path(args.cache), args.device, smoke_overrides(32, 9) if args.smoke else [])
        (out / "p2g_runs.json").write_text(json.dumps(res, indent=1))
    if not args.no_bench:
        res["bench"] = bench_rows(args.device)
        (out / "p2g_runs.json").write_text(json.dumps(res, indent=1))
    print("device:", res["device"])
    for r in res["shots"]:
        print(f"{r['shot']:12s} det {int(r['deterministic'])} sort {str(r['sort_every']):10s} {r['ms_substep']:.3f} ms/substep "
              f"{r['G_per_s']:.2f} G/s  scatter {r['ms_scatter']:.3f}  sort {r['ms_sort']:.3f}  ({r['substeps']}) "
              f"fastest {r['cells_a_substep']:.4f} cells a substep -> every {r['cadence_now']}")
    for r in res["bench"]:
        print(f"{r['scene']:6s} {r['grid_n']} det {r['det']} {r.get('G_per_s', 0):.2f} G/s "
              f"p2g {r.get('ms_p2g', 0):.3f} ms  {r.get('error', '')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
