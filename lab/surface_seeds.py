"""The surfacer's error on random samples over many seeds: for each shape, count and setting,
the range over seeds of the vertex mean, the surface error (area-weighted) and the max, in
particle spacings h, and how many seeds put a vertex past 1 h. With --edges, also where the random box's edges sit: the signed inset of the vertices near
exactly two faces, and at the edge's bisector (mean / p99 / max), smoothed and raw (no flow).

    python lab/surface_seeds.py [--counts 100000 1000000] [--seeds 12 6] [--device cpu] [--out X.csv] [--edges]
"""

import argparse
import csv
import sys

import numpy as np
import warp as wp

from mpmfx.bench.surface_cases import OURS, sample_shape, shape_sdf, surface_error
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles


def mesh(shape: str, count: int, seed: int, label: str, device: str, **overrides):
    """(vertices, faces, h) of our surface of a random sample at setting OURS[label]."""
    x, h = sample_shape(shape, count, "random", seed=seed)
    setting = {**OURS[label], **overrides}
    params = SurfaceParams(
        PARTICLE_RADIUS_PER_SPACING * h, voxel_size=setting.pop("voxel_h") * h, dense_output=False, **setting
    )
    m = surface_particles(x, None, params, device=device).mesh
    return m.vertices, m.faces, h


def sweep(counts, seeds, device):
    rows = []
    for shape in ("sphere", "torus", "box"):
        sdf, _, _ = shape_sdf(shape)
        for count, n_seeds in zip(counts, seeds):
            for label in OURS:
                r = []
                for seed in range(n_seeds):
                    v, f, h = mesh(shape, count, seed, label, device)
                    e = np.abs(sdf(v.astype(np.float64))) / h
                    r.append((e.mean(), surface_error(v, f, sdf) / h, e.max()))
                r = np.array(r)
                row = {
                    "shape": shape,
                    "count": count,
                    "setting": label,
                    "seeds": n_seeds,
                    "mean_lo": r[:, 0].min(),
                    "mean_hi": r[:, 0].max(),
                    "surface_lo": r[:, 1].min(),
                    "surface_hi": r[:, 1].max(),
                    "max_lo": r[:, 2].min(),
                    "max_hi": r[:, 2].max(),
                    "seeds_over_1h": int((r[:, 2] > 1.0).sum()),
                }
                rows.append(row)
                print(
                    f"{shape:6} {count:>8} {label:4} x{n_seeds:<3} vertex mean {row['mean_lo']:.3f}-{row['mean_hi']:.3f} h, "
                    f"surface {row['surface_lo']:.3f}-{row['surface_hi']:.3f} h, max {row['max_lo']:.2f}-{row['max_hi']:.2f} h, "
                    f"over 1 h: {row['seeds_over_1h']}",
                    flush=True,
                )
    return rows


def edges(counts, device, n_seeds: int = 3):
    """The random box's edges: vertices within 4 h of exactly two faces; the bisector: those
    within 0.15 h of equal distance to both. Inset: h inside the box (positive inside)."""
    sdf, _, half = shape_sdf("box")
    half = np.asarray(half)
    for count in counts:
        for label in OURS:
            for overrides in ({}, {"smooth_iters": 0}):
                out = []
                for seed in range(n_seeds):
                    v, _, h = mesh("box", count, seed, label, device, **overrides)
                    v = v.astype(np.float64)
                    d = np.sort(np.abs(np.abs(v) - half) / h, axis=1)
                    inset = -sdf(v) / h
                    edge = (d[:, 1] < 4) & (d[:, 2] > 4)
                    bis = edge & (np.abs(d[:, 0] - d[:, 1]) < 0.15)
                    out.append((inset[edge].mean(), inset[bis].mean(), np.percentile(inset[bis], 99), inset[bis].max()))
                m = np.mean(out, axis=0)
                what = "raw field (no flow)" if overrides else "smoothed"
                print(
                    f"box {count:>8} {label:4} {what:20} edge vertices' mean inset {m[0]:+.3f} h; "
                    f"at the bisector mean / p99 / max {m[1]:.3f} / {m[2]:.3f} / {m[3]:.3f} h ({n_seeds} seeds)",
                    flush=True,
                )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[100_000, 1_000_000])
    ap.add_argument(
        "--seeds", type=int, nargs="+", default=[12, 6], help="seeds per count (one number: the same for all)"
    )
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out", default=None, help="also write the rows as CSV here")
    ap.add_argument("--edges", action="store_true", help="also the random box's edge profile")
    args = ap.parse_args()
    seeds = args.seeds * len(args.counts) if len(args.seeds) == 1 else args.seeds
    if len(seeds) != len(args.counts):
        print(f"error: --seeds {' '.join(map(str, args.seeds))}: give one number or one per count", file=sys.stderr)
        return 2
    wp.config.quiet = True
    wp.init()
    rows = sweep(args.counts, seeds, args.device)
    if args.out:
        with open(args.out, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        print("wrote", args.out)
    if args.edges:
        edges(args.counts, args.device)
    return 0


if __name__ == "__main__":
    sys.exit(main())
