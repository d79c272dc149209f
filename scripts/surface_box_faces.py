"""Where the random box's surface error comes from: vertices sorted by distance to the nearest
edge (faces, edges, corners: mean |error|, signed mean, spread, in particle spacings h), then
each face away from the edges with its plane's phase on the voxel grid (0 = on a voxel plane)
and on the 8-voxel block grid (voxels of its block that lie inside the face), and the error of
the vertices on grid edges across the face alone (the vertex mean over all of a face's
vertices depends on the voxel phase: near phase 0 marching cubes puts many vertices exactly
on the voxel plane). README: "Where a flat face cuts its block".

    python3 scripts/surface_box_faces.py --counts 100000 1000000 --device cpu
    python3 scripts/surface_box_faces.py --counts 1000000 --close-voids 1   # SurfaceParams.close_voids = 1 h
"""
import argparse

import numpy as np

from mpmfx.bench.surface_cases import BOX_HALF, OURS, sample_shape
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles


def edge_distance(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance to the nearest box edge, distance to the nearest corner) of (n, 3) points, m."""
    q = np.abs(v) - BOX_HALF
    out = np.maximum(q, 0.0)
    edge = np.full(len(v), np.inf)
    for a, b, c in ((0, 1, 2), (0, 2, 1), (1, 2, 0)):
        edge = np.minimum(edge, np.sqrt(q[:, a] ** 2 + q[:, b] ** 2 + out[:, c] ** 2))
    return edge, np.linalg.norm(q, axis=1)


def report(count: int, label: str, device: str, seed: int, close_voids: float = 0.0) -> None:
    x, h = sample_shape("box", count, "random", seed=seed)
    setting = dict(OURS[label])
    voxel = setting.pop("voxel_h") * h
    params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False,
                           close_voids=close_voids * h, **setting)
    v = surface_particles(x, None, params, device=device).mesh.vertices.astype(np.float64)
    q = np.abs(v) - BOX_HALF
    err = (np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)) / h
    edge, corner = (d / h for d in edge_distance(v))
    print(f"random box, {len(x)} particles, {label}, close_voids {close_voids:g} h: mean |e| {np.abs(err).mean():.4f} h, max {np.abs(err).max():.3f} h, "
          f"signed {err.mean():+.4f} h")
    classes = {"face, > 5 h from an edge": edge > 5, "face, 3-5 h": (edge > 3) & (edge <= 5),
               "edge, 1-3 h": (edge > 1) & (edge <= 3) & (corner > 3), "edge, < 1 h": (edge <= 1) & (corner > 3),
               "corner, < 3 h": corner <= 3}
    for name, m in classes.items():
        if m.any():
            print(f"  {name:26s} {m.mean():6.1%} of vertices  |e| {np.abs(err[m]).mean():.4f}  signed {err[m].mean():+.4f}"
                  f"  std {err[m].std():.4f}  max {np.abs(err[m]).max():.3f}")
    g = v / voxel  # grid coordinates: voxel planes at integers (the surfacer's grid is aligned to 0)
    for a in range(3):
        across = np.all([np.abs(g[:, b] - np.round(g[:, b])) < 1e-3 for b in range(3) if b != a], axis=0)
        for sign in (-1, 1):
            m = (edge > 5) & (np.argmax(np.abs(v) / BOX_HALF, axis=1) == a) & (np.sign(v[:, a]) == sign)
            plane = sign * BOX_HALF[a] / voxel
            inside = plane - 8 * np.floor(plane / 8) if sign > 0 else 8 * np.ceil(plane / 8) - plane
            n = m & across
            print(f"  face {'xyz'[a]}{'+' if sign > 0 else '-'}: voxel phase {plane % 1:.2f}, block fill {inside:.1f} voxels, "
                  f"|e| {np.abs(err[m]).mean():.4f} signed {err[m].mean():+.4f}; edges across it: "
                  f"|e| {np.abs(err[n]).mean():.4f} std {err[n].std():.4f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[100_000, 1_000_000])
    ap.add_argument("--labels", nargs="+", default=list(OURS), choices=list(OURS))
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--close-voids", type=float, default=0.0, help="SurfaceParams.close_voids in particle spacings (0 = off)")
    args = ap.parse_args()
    for count in args.counts:
        for label in args.labels:
            report(count, label, args.device, args.seed, args.close_voids)


if __name__ == "__main__":
    main()
