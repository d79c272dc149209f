"""Where the largest vertex errors of random samples sit, and which stage puts them there
(issue 17). For each shape and setting (mpmfx.bench.surface_cases.OURS) on a uniformly random
sample: the vertices whose error |sdf| exceeds --threshold (in particle spacings h), each with

- where the surface of each stage crosses the analytic normal through the vertex (signed, h,
  negative inside): "raw" the distance the blur starts from (the redistance pass, after the closing
  when --close-voids), "blur" the blurred distance without the inward limit, "limited" the
  blur with it (what is meshed);
- how many particles lie within 1.5 h of the point 1 h under the analytic surface there
  (a sample void reads fewer than the typical count, printed alongside);
- on the box, the distance to the nearest edge (h).

Then, on the box, the signed / absolute mean error (h) of each stage's own mesh by distance
to the nearest edge (the raw distance meshed without the blur, the blur without the limit,
the result). The stages are read by wrapping the smooth pass (a diagnostic hook, this script only).

    PYTHONPATH=. python3 scripts/surface_max_error.py --counts 1000000 --device cpu
    PYTHONPATH=. python3 scripts/surface_max_error.py --counts 100000 --shapes box --sampling lattice
"""
import argparse
import dataclasses

import numpy as np

from mpmfx.bench.surface_cases import BOX_HALF, OURS, sample_shape, shape_sdf
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, sparse, surface_particles, variants

EDGE_BINS = ((0, 0.5), (0.5, 1), (1, 2), (2, 3), (3, 5), (5, np.inf))  # distance to the nearest box edge, h


class Stages:
    """Wraps the smooth pass (variants.Variant.smooth): records the distance it starts from and its result (voxels, by
    active block), and the flow without the 0.5 r inward limit (an edge keeps its own: twice its
    samples' noise); `mesh` = "raw" / "blur" makes the surfacer mesh that stage instead of the
    limited flow."""

    def __init__(self):
        self.inner, self.mesh, self.fields, self.origin = {v.name: v.smooth for v in (variants.BY_BLOCK, variants.BY_VOXEL)}, None, {}, np.zeros(3)

    def __call__(self, bcoord, bmap, dist, iters, tiles, *, limit, edges):
        inner = self.inner[variants.variant(dist.device).name]
        out = inner(bcoord, bmap, dist, iters, tiles, limit=limit, edges=edges)
        blur = inner(bcoord, bmap, dist, iters, tiles, limit=1e9, edges=edges)
        self.fields = {"bcoord": bcoord.numpy(), "raw": dist.numpy().copy(), "blur": blur.numpy(), "limited": out.numpy()}
        return {"raw": dist, "blur": blur}.get(self.mesh, out)


def sampler(fields: dict, key: str, origin: np.ndarray, voxel: float):
    """World points (n, 3) -> trilinear value of a recorded field (voxels); NaN off the active blocks."""
    bc = fields["bcoord"]
    data = fields[key].reshape(-1, 8, 8, 8)
    lo = bc.min(axis=0)
    index = np.full(bc.max(axis=0) - lo + 1, -1, np.int64)
    index[tuple((bc - lo).T)] = np.arange(len(bc))

    def f(p: np.ndarray) -> np.ndarray:
        q = (p - origin) / voxel
        i0 = np.floor(q).astype(np.int64)
        fr = q - i0
        out = np.zeros(len(p))
        for corner in np.ndindex(2, 2, 2):
            ii = i0 + corner
            b = ii // 8 - lo
            ok = np.all((b >= 0) & (b < index.shape), axis=1)
            bi = np.where(ok, index[tuple(np.clip(b, 0, np.array(index.shape) - 1).T)], -1)
            li = ii % 8
            val = np.where(bi >= 0, data[np.maximum(bi, 0), li[:, 0], li[:, 1], li[:, 2]], np.nan)
            out += np.prod(np.where(corner, fr, 1 - fr), axis=1) * val
        return out
    return f


def normals(sdf, p: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    n = np.stack([sdf(p + eps * e) - sdf(p - eps * e) for e in np.eye(3)], 1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def crossing(f, q: np.ndarray, n: np.ndarray, h: float, span: float = 3.0, steps: int = 241) -> np.ndarray:
    """Signed offset (h) from q along n of the zero of f nearest to q (NaN if none within span h)."""
    ts = np.linspace(-span, span, steps)
    vals = np.stack([f(q + t * h * n) for t in ts], 1)
    out = np.full(len(q), np.nan)
    for i, s in enumerate(vals):
        c = np.where(s[:-1] * s[1:] < 0)[0]
        if len(c):
            k = c[np.argmin(np.abs(ts[c]))]
            out[i] = ts[k] + (ts[k + 1] - ts[k]) * s[k] / (s[k] - s[k + 1])
    return out


def edge_distance(q: np.ndarray) -> np.ndarray:
    """Distance (m) of points q on the box's surface to its nearest edge."""
    return np.sort(BOX_HALF - np.abs(q), axis=1)[:, 1]


def report(shape: str, count: int, sampling: str, label: str, args, hook: Stages) -> None:
    from scipy.spatial import cKDTree

    x, h = sample_shape(shape, count, sampling)
    setting = dict(OURS[label])
    voxel = setting.pop("voxel_h") * h
    params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False,
                           close_voids=args.close_voids * h, **setting)
    hook.mesh = None
    res = surface_particles(x, None, params, device=args.device)
    fields = hook.fields
    sdf, _, _ = shape_sdf(shape)
    v = res.mesh.vertices.astype(np.float64)
    e = sdf(v) / h
    print(f"{sampling} {shape} {len(x)} {label}: mean |e| {np.abs(e).mean():.4f} h, max {np.abs(e).max():.3f} h, "
          f"signed {e.mean():+.4f} h, sd {e.std():.4f} h")
    big = np.argsort(-np.abs(e))
    big = big[: max(int(np.sum(np.abs(e) > args.threshold)), args.top)]
    n = normals(sdf, v[big])
    q = v[big] - sdf(v[big])[:, None] * n
    offs = {k: crossing(sampler(fields, k, hook.origin, voxel), q, n, h) for k in ("raw", "blur", "limited")}
    tree = cKDTree(x)
    count_at = lambda p, nn: np.array([len(a) for a in tree.query_ball_point(p - h * nn, 1.5 * h)])
    some = np.random.default_rng(0).choice(len(v), min(3000, len(v)), replace=False)
    ns = normals(sdf, v[some])
    typical = count_at(v[some] - sdf(v[some])[:, None] * ns, ns)
    near = count_at(q, n)
    print(f"  {np.sum(np.abs(e) > args.threshold)} vertices over {args.threshold} h ({np.sum(e[big] < -args.threshold)} inward); "
          f"particles within 1.5 h of 1 h under the surface: typical {typical.mean():.1f} +- {typical.std():.1f}, "
          f"here median {np.median(near):.0f}")
    for j, i in enumerate(big[: args.list]):
        line = (f"    e {e[i]:+.3f}  raw {offs['raw'][j]:+.3f}  blur {offs['blur'][j]:+.3f}  limited {offs['limited'][j]:+.3f}"
                f"  particles {near[j]:2d}")
        if shape == "box":
            line += f"  edge {edge_distance(q[j:j + 1])[0] / h:.2f} h"
        print(line)
    if shape == "box":
        for stage in ("raw", "blur", None):
            hook.mesh = stage
            m = surface_particles(x, None, params, device=args.device).mesh.vertices.astype(np.float64)
            es = sdf(m) / h
            ed = edge_distance(m - sdf(m)[:, None] * normals(sdf, m)) / h
            cells = [f"[{a:g},{b:g}) {es[(ed >= a) & (ed < b)].mean():+.3f}/{np.abs(es[(ed >= a) & (ed < b)]).mean():.3f}"
                     for a, b in EDGE_BINS]
            print(f"  mesh of {stage or 'limited'}: mean {np.abs(es).mean():.4f} h; signed/|e| by edge distance (h): " + " ".join(cells))
        hook.mesh = None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[100_000])
    ap.add_argument("--shapes", nargs="+", default=["sphere", "torus", "box"])
    ap.add_argument("--labels", nargs="+", default=list(OURS))
    ap.add_argument("--sampling", default="random")
    ap.add_argument("--threshold", type=float, default=0.8, help="list vertices with |error| above this (h)")
    ap.add_argument("--top", type=int, default=10, help="at least this many of the largest errors")
    ap.add_argument("--list", type=int, default=12, help="print this many of them")
    ap.add_argument("--close-voids", type=float, default=0.0, help="SurfaceParams.close_voids in h")
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    hook = Stages()
    grid_init = sparse.SparseGrid.__init__

    def record_origin(grid, lo, hi, params):
        grid_init(grid, lo, hi, params)
        hook.origin = grid.origin.copy()

    variants.BY_BLOCK, variants.BY_VOXEL = (dataclasses.replace(v, smooth=hook) for v in (variants.BY_BLOCK, variants.BY_VOXEL))
    sparse.SparseGrid.__init__ = record_origin
    for count in args.counts:
        for shape in args.shapes:
            for label in args.labels:
                report(shape, count, args.sampling, label, args, hook)


if __name__ == "__main__":
    main()
