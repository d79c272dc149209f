"""The thin-sheet case at scale on a GPU (development aid): a disc one particle spacing thick
(`surface_cases.sample_sheet`, random and lattice), surfaced at "fine" as the surface stage
does (`min_feature_particles` included, so the component labels run: a sheet has no INSIDE
tile), one profiled call after three timed ones; the top kernels by time.

    python3 scripts/surface_sheet_profile.py 1000000 3000000
"""
import sys
import time

import numpy as np
import warp as wp

from mpmfx.bench.surface_cases import OURS, PARTICLE_RADIUS_PER_SPACING, sample_sheet
from mpmfx.surface import SurfaceParams, surface_particles

wp.config.quiet = True
wp.init()
dev = wp.get_device("cuda")
print(dev.name)
for count in [int(c) for c in sys.argv[1:]]:
    for sampling in ("random", "lattice"):
        x, h = sample_sheet(count, sampling)
        xd = wp.array(x, dtype=wp.vec3, device=dev)
        kw = dict(OURS["fine"])
        params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=kw.pop("voxel_h") * h, dense_output=False, **kw)
        surface_particles(xd, None, params)  # warm-up (compiles once)
        seconds = []
        for _ in range(3):
            wp.synchronize_device(dev)
            t0 = time.perf_counter()
            res = surface_particles(xd, None, params)
            seconds.append(time.perf_counter() - t0)
        wp.timing_begin(cuda_filter=wp.TIMING_ALL)
        surface_particles(xd, None, params)
        kernels = {}
        for r in wp.timing_end():
            rec = kernels.setdefault(r.name.split("(")[0].replace("forward kernel ", "")[:40], [0, 0.0])
            rec[0] += 1
            rec[1] += r.elapsed
        print(f"sheet {sampling} {len(x)} fine: whole call median {1e3 * np.median(seconds):.1f} ms, device "
              f"{1e3 * res.stats['device']:.1f} ms, blocks {res.stats['active_blocks']}, vertices {len(res.mesh.vertices)}")
        print("   " + "; ".join(f"{k} {ms:.1f}ms x{c}" for k, (c, ms) in sorted(kernels.items(), key=lambda kv: -kv[1][1])[:12]),
              flush=True)
