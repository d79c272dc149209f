"""GPU run of the surfacing figures (README): `mpmfx bench surface` at the given counts (ours,
plus the peers asked for with --peers), the thin-sheet case (isotropic and anisotropic kernels,
and the same peers) at --sheet particles, then how long the copy to the host takes, pageable against pinned
staging, at the largest count. Writes surface.csv/json and surface_sheet.csv/json under --out.

    python3 scripts/surface_gpu.py --out $OUT                      # 1M and 10M, ours only, sheet 1M
    python3 scripts/surface_gpu.py --counts 10000000 --peers splashsurf newton newton-aniso --out $OUT
    python3 scripts/surface_gpu.py --counts 1000000 --peers newton newton-aniso --sheet 1000000 --out $OUT  # sheet vs Newton
"""
import argparse
import time

import numpy as np
import warp as wp

from mpmfx.bench.report import write_rows
from mpmfx.bench.surface import choose_peers
from mpmfx.bench.surface_cases import HEADER, OURS, SHEET_COUNTS, bench_sheet, bench_surface, sample_shape
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams
from mpmfx.surface.sparse import surface_on_device

ap = argparse.ArgumentParser()
ap.add_argument("--counts", type=int, nargs="+", default=[1_000_000, 10_000_000])
ap.add_argument("--peers", nargs="*", default=[], help="peers to run too (their README rows are from an earlier run)")
ap.add_argument("--sheet", type=int, default=SHEET_COUNTS["full"], help="particles in the thin-sheet case (0: skip)")
ap.add_argument("--device", default="cuda")
ap.add_argument("--out", default="renders/bench")
ap.add_argument("--repeats", type=int, default=3)
args = ap.parse_args()
wp.config.quiet = True
wp.init()
print(wp.get_device(args.device).name, flush=True)
print(HEADER, flush=True)
peers = choose_peers(args.peers, quick=False) if args.peers else []
rows = bench_surface(args.counts, ("sphere", "torus", "box"), ("lattice", "random"), args.device,
                     peers=peers, repeats=args.repeats)
print("table:", write_rows(rows, args.out, "surface"), flush=True)
if args.sheet:
    sheet = bench_sheet(args.sheet, args.device, peers=peers)  # the same peers on the sheet
    print("thin sheet:", write_rows(sheet, args.out, "surface_sheet"), flush=True)
for r in rows:
    if "stages" in r and r["stages"]:
        print(r["shape"], r["sampling"], r["method"], {k: v for k, v in r["stages"].items()}, flush=True)
# the host copy, pageable against pinned, at the largest count (fast setting)
count = max(args.counts)
with wp.ScopedDevice(args.device):
    for shape, sampling in (("sphere", "lattice"), ("torus", "random")):
        x, h = sample_shape(shape, count, sampling)
        xd = wp.array(x, dtype=wp.vec3)
        p = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=OURS["fast"]["voxel_h"] * h,
                          smooth_iters=OURS["fast"]["smooth_iters"], dense_output=False)
        for pinned in (False, True, False, True):
            times = []
            for _ in range(3):
                t0 = time.perf_counter()
                d = surface_on_device(xd, None, p)
                wp.synchronize()
                t1 = time.perf_counter()
                res = d.download(p, pinned=pinned)
                t2 = time.perf_counter()
                times.append((t1 - t0, t2 - t1, res.stats["download_mesh"], res.stats["download_leaves"]))
            dev, down, mesh, leaves = np.median(np.array(times), axis=0)
            print(f"{shape} {sampling} n={count} pinned={pinned}: device {dev * 1e3:.1f} ms + download {down * 1e3:.1f} ms "
                  f"(mesh {mesh * 1e3:.1f}, leaves {leaves * 1e3:.1f}) = {(dev + down) * 1e3:.1f} ms, "
                  f"{count / (dev + down) / 1e6:.0f} M particles/s; {len(res.mesh.vertices)} vertices, "
                  f"{len(res.sparse.block_ijk)} leaves", flush=True)
