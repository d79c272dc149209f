"""Does the closing glue a droplet to a body? One lone particle d spacings beyond the outermost
particle of a 20k random sphere (along that particle's ray), surfaced with and without
SurfaceParams.close_voids: mesh pieces, and how far the mesh reaches along the ray above the
analytic sphere (h; about d where the droplet is bridged to the body or kept as its own piece,
under 1 h where it is gone). "fine" removes blobs of fewer than 8 particles, so there a lone
droplet that is not bridged disappears; "fast" keeps it as a second piece.
docs/surfacing-log.md, "The distance at the crossing, and why the closing stays opt-in".

    PYTHONPATH=. python3 scripts/surface_droplet.py --close 0 0.5 0.75 1   # 2-core CPU: ~2 min
"""
import argparse

import numpy as np

from mpmfx.bench.surface_cases import OURS, SPHERE_RADIUS, mesh_stats, sample_shape
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--close", type=float, nargs="+", default=[0.0, 0.5, 1.0], help="close_voids in particle spacings")
    ap.add_argument("--gaps", type=float, nargs="+", default=[2.0, 2.5, 3.0, 3.5, 4.0, 5.0],
                    help="droplet distance beyond the outermost particle, in particle spacings")
    ap.add_argument("--labels", nargs="+", default=["fine", "fast"], choices=list(OURS))
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    x, h = sample_shape("sphere", 20_000, "random")
    p = x[np.argmax(np.linalg.norm(x, axis=1))].astype(np.float64)  # the outermost particle
    ray = p / np.linalg.norm(p)
    for label in args.labels:
        setting = dict(OURS[label])
        voxel = setting.pop("voxel_h") * h
        for close in args.close:
            cells = []
            for gap in args.gaps:
                y = np.vstack([x, (p + gap * h * ray)[None].astype(np.float32)])
                params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False,
                                       close_voids=close * h, **setting)
                mesh = surface_particles(y, None, params, device=args.device).mesh
                _, pieces = mesh_stats(mesh.vertices, mesh.faces)
                v = mesh.vertices.astype(np.float64)
                along = v @ ray
                near_ray = np.linalg.norm(v - along[:, None] * ray, axis=1) < 3 * h
                reach = (along[near_ray].max() - SPHERE_RADIUS) / h
                cells.append(f"{gap:g} h: {pieces} piece{'s' if pieces > 1 else ''}, reach {reach:+.2f} h")
            print(f"{label} close_voids {close:g} h | " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
