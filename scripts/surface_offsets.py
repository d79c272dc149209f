"""How the surfacer's error moves with where the shape sits on the voxel grid: each shape
surfaced with its particles shifted by fractions of a voxel, "fast" and "fine", on the default
Warp device. Prints the vertex mean and max (marching cubes' vertices lie on grid edges, so
they sample a flat face differently as it moves between voxel planes) beside the area-weighted
surface error (surface_cases.surface_error), all in particle spacings h.

    python3 scripts/surface_offsets.py [count] [--shapes box sphere] [--sampling random]
"""
import argparse

import numpy as np
import warp as wp

from mpmfx.bench.surface_cases import OURS, PARTICLE_RADIUS_PER_SPACING, sample_shape, shape_sdf, surface_error
from mpmfx.surface import SurfaceParams, surface_particles

ap = argparse.ArgumentParser()
ap.add_argument("count", type=int, nargs="?", default=1_000_000)
ap.add_argument("--shapes", nargs="+", default=["box"])
ap.add_argument("--sampling", default="random")
ap.add_argument("--offsets", type=float, nargs="+", default=[0.0, 0.25, 0.5, 0.75], help="voxels")
args = ap.parse_args()
wp.config.quiet = True
wp.init()
print(wp.get_device().name, flush=True)
for shape in args.shapes:
    x, h = sample_shape(shape, args.count, args.sampling)
    sdf = shape_sdf(shape)[0]
    for label, kw in OURS.items():
        kw = dict(kw)
        params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=kw.pop("voxel_h") * h, dense_output=False, **kw)
        for offset in args.offsets:
            shift = np.float32(offset * params.voxel_size)
            mesh = surface_particles(x + shift, None, params).mesh
            v = mesh.vertices.astype(np.float64) - shift
            e = np.abs(sdf(v)) / h
            print(f"{shape} {args.sampling} {len(x)} {label:4s} offset {offset:4.2f} voxel: vertex mean {e.mean():.4f} "
                  f"max {e.max():.3f}  surface {surface_error(v, mesh.faces, sdf) / h:.4f} h", flush=True)
