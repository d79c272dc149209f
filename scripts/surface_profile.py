"""Per-kernel profile of the sparse surfacer (development aid): one bench row per case
(`mpmfx.bench.surface_cases.measure`: device-resident, median of 3), then the top kernels of
one more call.

    python3 scripts/surface_profile.py --count 10000000 --configs 0.6:1 0.5:2
    python3 scripts/surface_profile.py --device cpu --count 100000 --samplings random --configs 0.6:2 0.5:5
configs are VOXEL_H:SMOOTH_ITERS with voxel = VOXEL_H * particle spacing h, at the shipped
particle radius (mpmfx.surface.PARTICLE_RADIUS_PER_SPACING * h). On the CPU Warp's timer
sees no kernels, so each launch is timed around the call (CPU launches are synchronous): a
launch split across threads (mpmfx.surface.launch) counts once, whole, and a sequence of them
(the weight blur) under its first kernel's name.
"""
import argparse
import contextlib
import time

import warp as wp

from mpmfx.bench.surface_cases import format_row, measure, sample_shape
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles



@contextlib.contextmanager
def cpu_kernel_timer(agg: dict):
    """Times every CPU launch of the surfacer into agg[kernel key] = [launches, ms]: plain
    wp.launch calls, and the split launches of mpmfx.surface.launch whole (their chunks' own
    launches, recorded commands, are not seen by wp.launch)."""
    from mpmfx.surface import classify, components, field, flood, gather, launch, sharpen

    def record(key, t0):
        rec = agg.setdefault(key, [0, 0.0])
        rec[0] += 1
        rec[1] += 1000.0 * (time.perf_counter() - t0)

    def timed(fn, key_of):
        def call(*a, **k):
            if k.get("record_cmd"):
                return fn(*a, **k)
            t0 = time.perf_counter()
            out = fn(*a, **k)
            record(key_of(a), t0)
            return out
        return call

    saved = [(wp, "launch", wp.launch)] + [(m, name, getattr(m, name)) for m in (launch, classify, flood, components, sharpen, field, gather)
                                            for name in ("launch_split", "launch_sequence", "launch_split_scratch")
                                            if hasattr(m, name)]
    depth = [0]

    def outer(fn, key_of):  # a split launch's own plain launches (small dims) count once, under it
        inner = timed(fn, key_of)

        def call(*a, **k):
            depth[0] += 1
            try:
                return inner(*a, **k)
            finally:
                depth[0] -= 1
        return call

    plain = timed(wp.launch, lambda a: a[0].key)
    wp.launch = lambda *a, **k: (saved[0][2](*a, **k) if depth[0] else plain(*a, **k))
    for m, name, fn in saved[1:]:
        key_of = (lambda a: "seq " + a[1][0][0].key) if name == "launch_sequence" else (lambda a: a[1].key)
        setattr(m, name, outer(fn, key_of))
    try:
        yield
    finally:
        for m, name, fn in saved:
            setattr(m, name, fn)


ap = argparse.ArgumentParser()
ap.add_argument("--count", type=int, default=10_000_000)
ap.add_argument("--shapes", nargs="+", default=["sphere"])
ap.add_argument("--samplings", nargs="+", default=["lattice", "random"])
ap.add_argument("--configs", nargs="+", default=["0.6:1", "0.5:2"])
ap.add_argument("--device", default="cuda")
ap.add_argument("--top", type=int, default=10, help="kernels listed per case")
args = ap.parse_args()
wp.config.quiet = True
wp.init()
for shape in args.shapes:
    for sampling in args.samplings:
        x, h = sample = sample_shape(shape, args.count, sampling)
        xd = wp.array(x, dtype=wp.vec3, device=args.device)
        for cfg in args.configs:
            vh, iters = float(cfg.split(":")[0]), int(cfg.split(":")[1])
            row = measure(shape, args.count, sampling, device=args.device, sample=sample, repeats=3, label=cfg,
                          voxel_h=vh, smooth_iters=iters, dense_output=False)
            print(format_row(row), row["stages"], flush=True)
            params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=vh * h, smooth_iters=iters,
                                   dense_output=False)
            agg = {}
            if xd.device.is_cpu:
                with cpu_kernel_timer(agg):
                    surface_particles(xd, None, params)
            else:
                wp.timing_begin(cuda_filter=wp.TIMING_ALL)
                surface_particles(xd, None, params)
                for r in wp.timing_end():
                    a = agg.setdefault(r.name.split("(")[0][:50], [0, 0.0])
                    a[0] += 1
                    a[1] += r.elapsed
            print("   ", "; ".join(f"{k.replace('forward kernel ', '')} {ms:.1f}ms x{c}" for k, (c, ms) in
                                 sorted(agg.items(), key=lambda kv: -kv[1][1])[:args.top]), flush=True)
