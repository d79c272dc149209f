"""The surfacer's GPU times and accuracy in one short run (the figures of the README's H100
table that the code under them moves): per shape, sampling and setting at one count, the
device time and the time with the copy of the mesh and sparse leaves to the host (end to
end, M particles/s, as the surface stage asks: no dense level set),
and the mean / max vertex error and the area-weighted surface error (surface_cases.surface_error). `scripts/surface_gpu.py` (the full bench: pieces, jitter,
peers, the sheet) takes longer than one device call at 10M.

    python3 scripts/surface_gpu_times.py [count] [--sheet N] [--calls 3] [--labels fast fine round]
default 10M, every setting of OURS, the median of 3 calls after a warm-up; $OUT/surface_times.csv
"""
import os
import sys
import time

import numpy as np
import warp as wp

from mpmfx.bench.report import print_table, write_rows
from mpmfx.bench.surface_cases import OURS, PARTICLE_RADIUS_PER_SPACING, bench_sheet, sample_shape, shape_sdf, surface_error
from mpmfx.surface import SurfaceParams, surface_particles

args = sys.argv[1:]
sheet = int(args[args.index("--sheet") + 1]) if "--sheet" in args else 0
calls = int(args[args.index("--calls") + 1]) if "--calls" in args else 3
labels = args[args.index("--labels") + 1:] if "--labels" in args else list(OURS)  # last on the line
count = int(args[0]) if args and not args[0].startswith("--") else 10_000_000
out = os.environ.get("OUT", "renders/bench")
wp.config.quiet = True
wp.init()
dev = wp.get_device("cuda")
print(dev.name, flush=True)
rows = []
for shape in ("sphere", "torus", "box"):
    for sampling in ("lattice", "random"):
        x, h = sample_shape(shape, count, sampling)
        sdf, _, _ = shape_sdf(shape)
        xd = wp.array(x, dtype=wp.vec3, device=dev)
        for label in labels:
            kw = dict(OURS[label])
            # as the surface stage (sparse leaves, no dense level set: that costs 0.5-1.9 s at 10M)
            params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=kw.pop("voxel_h") * h,
                                   dense_output=False, **kw)
            surface_particles(xd, None, params)  # warm-up (compiles once)
            device_s, total_s = [], []
            for _ in range(calls):
                wp.synchronize_device(dev)
                t0 = time.perf_counter()
                res = surface_particles(xd, None, params)
                total_s.append(time.perf_counter() - t0)
                device_s.append(res.stats["device"])
            err = np.abs(sdf(res.mesh.vertices.astype(np.float64))) / h
            d, t = float(np.median(device_s)), float(np.median(total_s))
            rows.append({"shape": shape, "sampling": sampling, "particles": len(x), "method": f"mpmfx {label}",
                         "device_ms": 1e3 * d, "with_host_ms": 1e3 * t, "Mps_device": len(x) / d / 1e6,
                         "Mps_end_to_end": len(x) / t / 1e6, "err_mean_h": float(err.mean()),
                         "err_surface_h": surface_error(res.mesh.vertices, res.mesh.faces, sdf) / h,
                         "err_max_h": float(err.max()), "vertices": len(res.mesh.vertices), "calls": calls,
                         "Mps_end_to_end_min": len(x) / max(total_s) / 1e6, "device": dev.name})
            print_table(rows[-1:], list(rows[-1]))
print_table(rows, list(rows[0]))
print("table:", write_rows(rows, out, "surface_times"), flush=True)
if sheet:
    print("thin sheet:", write_rows(bench_sheet(sheet, "cuda"), out, "surface_sheet"), flush=True)
