"""CPU time of our settings beside splashsurf on the bench's 100k cases, alternating call by call
in one process (so a slow spell of the machine hits every method alike): the median of --calls
whole calls (host particles -> host mesh) after a warm-up, splashsurf on every core.

    python scripts/surface_cpu_times.py [--settings round fine] [--calls 7] [--count 100000]
"""
import argparse
import time

import numpy as np
import warp as wp

from mpmfx.bench.surface_cases import OURS, sample_shape
from mpmfx.bench.surface_peers import SPLASHSURF_SETTINGS, splashsurf_call
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--settings", nargs="+", default=["round", "fine"], choices=list(OURS))
    ap.add_argument("--calls", type=int, default=7)
    ap.add_argument("--count", type=int, default=100_000)
    args = ap.parse_args()
    wp.config.quiet = True
    wp.init()
    for shape in ("sphere", "torus", "box"):
        for sampling in ("lattice", "random"):
            x, h = sample_shape(shape, args.count, sampling)
            calls = {}
            for label in args.settings:
                setting = dict(OURS[label])
                params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=setting.pop("voxel_h") * h,
                                       dense_output=False, **setting)
                calls[label] = lambda params=params: surface_particles(x, None, params, device="cpu")
            kernel, cube = SPLASHSURF_SETTINGS[sampling]
            calls["splashsurf"] = splashsurf_call(x, h, kernel=kernel, cube=cube)
            for call in calls.values():
                call()
            seconds = {name: [] for name in calls}
            for _ in range(args.calls):
                for name, call in calls.items():
                    t0 = time.perf_counter()
                    call()
                    seconds[name].append(time.perf_counter() - t0)
            print(f"{shape:6} {sampling:7} " + "  ".join(f"{name} {np.median(s) * 1e3:6.1f} ms"
                                                          for name, s in seconds.items()), flush=True)


if __name__ == "__main__":
    main()
