"""The thin-sheet case at scale on a GPU (development aid): a disc one particle spacing thick
(`surface_cases.sample_sheet`, random and lattice), surfaced at "fine" as the surface stage
does (`min_feature_particles` included, so the component labels run: a sheet has no INSIDE
tile), one profiled call after three timed ones; the top kernels by time.

    python3 scripts/surface_sheet_profile.py 1000000 3000000
"""
import sys, time, numpy as np, warp as wp
wp.config.quiet = True; wp.init()
from mpmfx.bench.surface_cases import OURS, PARTICLE_RADIUS_PER_SPACING, sample_sheet
from mpmfx.surface import SurfaceParams, surface_particles
dev = wp.get_device("cuda"); print(dev.name)
for count in [int(c) for c in sys.argv[1:]]:
    for sampling in ("random", "lattice"):
        x, h = sample_sheet(count, sampling)
        xd = wp.array(x, dtype=wp.vec3, device=dev)
        kw = dict(OURS["fine"]); vh = kw.pop("voxel_h")
        p = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=vh * h, dense_output=False, **kw)
        surface_particles(xd, None, p)
        ts = []
        for _ in range(3):
            wp.synchronize_device(dev); t = time.perf_counter(); r = surface_particles(xd, None, p); ts.append(time.perf_counter() - t)
        wp.timing_begin(cuda_filter=wp.TIMING_ALL)
        surface_particles(xd, None, p)
        agg = {}
        for rr in wp.timing_end():
            k = rr.name.split("(")[0].replace("forward kernel ", "")[:40]; a = agg.setdefault(k, [0, 0.0]); a[0] += 1; a[1] += rr.elapsed
        print(f"sheet {sampling} {len(x)} fine: whole call median {1e3*np.median(ts):.1f} ms, device {1e3*r.stats['device']:.1f} ms, blocks {r.stats['active_blocks']}, vertices {len(r.mesh.vertices)}", flush=True)
        print("   " + "; ".join(f"{k} {ms:.1f}ms x{c}" for k, (c, ms) in sorted(agg.items(), key=lambda kv: -kv[1][1])[:12]), flush=True)
