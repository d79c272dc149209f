"""Accuracy of the surfacer with and without the gated closing (SurfaceParams.close_voids, in
particle spacings), on the bench's shapes, random and lattice, "fast" and "fine": mean / max /
p99 vertex error and the area-weighted surface error (h), volume error, pieces, seconds of the
whole call (a first call compiles) and of its device work.
Prints one table and writes surface_close_voids.csv under --out. Imports numpy, warp and mpmfx.

    PYTHONPATH=. python3 scripts/surface_close_voids.py --counts 1000000 10000000 --device cuda --out $OUT
    PYTHONPATH=. python3 scripts/surface_close_voids.py --counts 100000 --device cpu --out /tmp/close   # 2-core CPU: ~1 min

PYTHONPATH=. (from the repository root): a script's own folder comes first on sys.path, so
without it an installed mpmfx elsewhere would be measured instead of this checkout.
"""
import argparse
import csv
import os
import time

from mpmfx.bench.surface_cases import OURS, _row, sample_shape
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[1_000_000, 10_000_000])
    ap.add_argument("--close", type=float, nargs="+", default=[0.0, 1.0], help="close_voids in particle spacings")
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--out", default="renders/bench")
    args = ap.parse_args()
    rows = []
    for count in args.counts:
        for shape in ("sphere", "torus", "box"):
            for sampling in ("random", "lattice"):
                x, h = sample_shape(shape, count, sampling)
                for label, setting in OURS.items():
                    setting = dict(setting)
                    voxel = setting.pop("voxel_h") * h
                    for close in args.close:
                        params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False,
                                               close_voids=close * h, **setting)
                        t0 = time.perf_counter()
                        res = surface_particles(x, None, params, device=args.device)
                        seconds = time.perf_counter() - t0
                        r = _row(shape, sampling, x, h, label, "", seconds, res.mesh.vertices, res.mesh.faces)
                        r.update(count=count, close_voids_h=close, device=args.device)
                        rows.append(r)
                        print(f"{count:9d} {shape:6s} {sampling:7s} {label:4s} close {close:g} h: mean {r['err_mean_h']:.4f} "
                              f"surface {r['err_surface_h']:.4f} "
                              f"max {r['err_max_h']:.3f} p99 {r['err_p99_h']:.3f} h  volume {r['volume_err']:+.2%}  "
                              f"pieces {r['components']}  {seconds:.2f} s (device {1e3 * res.stats['device']:.0f} ms)", flush=True)
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "surface_close_voids.csv")
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("table:", path)


if __name__ == "__main__":
    main()
