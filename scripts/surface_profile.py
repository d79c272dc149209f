"""Device-resident timing and per-kernel GPU profile of the sparse surfacer (development aid).

    python3 scripts/surface_profile.py --count 10000000 --configs 1.0:1 0.5:2
configs are VOXEL_FACTOR:SMOOTH_ITERS with voxel = factor * particle radius (r = h / 2).
"""
import argparse
import time

import numpy as np
import warp as wp

from mpmfx.surface import sparse
from mpmfx.surface.bench import _row, format_row, sample_shape
from mpmfx.surface.params import SurfaceParams
from mpmfx.surface.reconstruct import surface_particles

ap = argparse.ArgumentParser()
ap.add_argument("--count", type=int, default=10_000_000)
ap.add_argument("--shapes", nargs="+", default=["sphere"])
ap.add_argument("--samplings", nargs="+", default=["lattice", "random"])
ap.add_argument("--configs", nargs="+", default=["1.0:1", "0.5:2"])
ap.add_argument("--kernels", action="store_true", help="print the top kernels of each run")
ap.add_argument("--device", default="cuda")
args = ap.parse_args()
DEVICE = args.device
wp.config.quiet = True
wp.init()
surface_particles(sample_shape("sphere", 500, "lattice")[0], None, SurfaceParams(0.01, dense_output=False), device=DEVICE)
for shape in args.shapes:
    for sampling in args.samplings:
        x, h = sample_shape(shape, args.count, sampling)
        xd = wp.array(x, dtype=wp.vec3, device=DEVICE)
        for cfg in args.configs:
            vf, iters = float(cfg.split(":")[0]), int(cfg.split(":")[1])
            params = SurfaceParams(particle_radius=0.5 * h, voxel_size=vf * 0.5 * h, smooth_iters=iters, dense_output=False)
            runs = []
            for _ in range(3):
                wp.synchronize()
                t0 = time.perf_counter()
                res = surface_particles(xd, None, params)
                runs.append((time.perf_counter() - t0, dict(sparse.last_stats)))
            dev = sorted(r[1]["device"] for r in runs)[1]
            row = _row(shape, sampling, x, h, f"ZB v{vf}r s{iters}", "-", dev, res.mesh.vertices, res.mesh.faces)
            print(format_row(row), f"| device {dev*1e3:.1f} ms, +download {runs[-1][1]['download']*1e3:.0f} ms;",
                  {k: v for k, v in runs[-1][1].items() if k not in ("device", "download")}, flush=True)
            if args.kernels:
                wp.timing_begin(cuda_filter=wp.TIMING_ALL)
                surface_particles(xd, None, params)
                agg = {}
                for r_ in wp.timing_end():
                    a = agg.setdefault(r_.name.split("(")[0][:50], [0, 0.0])
                    a[0] += 1
                    a[1] += r_.elapsed
                print("   ", "; ".join(f"{k.replace('forward kernel ', '')} {ms:.1f}ms x{c}" for k, (c, ms) in
                                     sorted(agg.items(), key=lambda kv: -kv[1][1])[:10]), flush=True)
