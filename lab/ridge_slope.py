"""How rough a pile's surface is at rest, against the surface's smoothing steps.

Runs a shot's simulation (cached) and surfaces its last frame (or `--frame`) once per value of
`surface.smooth_iters`, the shot's other surface settings kept; on the deposit's top (faces
facing up, more than two particle spacings above the floor) it measures:

- the angle between neighbouring faces' normals (degrees; mean and 95th percentile): ridges
  and grooves one or two voxels wide show as large angles between the faces across them;
- the bump height (mm; mean and 95th percentile): how far each vertex stands off the mean of
  its neighbours, along its normal (the finest roughness, a voxel or two across);
- the ridge height (mm; RMS and 95th percentile): the top as a height field (2 mm cells) less
  that field blurred over 15 mm (a Gaussian's sigma), on the flank: ridges and grooves a few
  centimetres across, which the 1-ring misses;

and, so that a smoother surface that has lost the pile's shape shows, the pile itself: its peak
(cm above the floor), the slope of its flank (the median slope of the blurred height field
between 20 % and 80 % of the peak's height, degrees) and the mesh's volume (litres).

    python lab/ridge_slope.py [pipeline/shots/sand_collapse.toml] [--iters 1 2 4 8] [--set KEY=VALUE ...]

Prints one table. On a 2-core CPU: the shot's simulation once (about a minute for
sand_collapse), then about a second a row; `--device cuda` surfaces on a GPU.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
from scipy.interpolate import griddata
from scipy.ndimage import gaussian_filter

from mpmfx.io.frames import ParticleFrame
from mpmfx.render.camera import solver_floor
from mpmfx.shotfile import load_shot_config
from mpmfx.stages.runner import ShotRun
from mpmfx.stages.surface import surface_params
from mpmfx.surface import surface_particles

ROOT = Path(__file__).resolve().parents[1]


def face_normals(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit normals (m, 3), areas (m,) m^2) of triangles f (m, 3) over vertices v (n, 3) m."""
    c = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    a = np.linalg.norm(c, axis=1)
    return c / np.maximum(a, 1e-30)[:, None], 0.5 * a


def neighbour_angles(f: np.ndarray, n: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Angles (degrees) between the normals of each two kept faces that share an edge."""
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    face = np.tile(np.arange(len(f)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, face = edges[order], face[order]
    same = np.all(edges[1:] == edges[:-1], axis=1)
    a, b = face[:-1][same], face[1:][same]
    both = keep[a] & keep[b]
    cos = np.clip(np.sum(n[a[both]] * n[b[both]], axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def bump_heights(v: np.ndarray, f: np.ndarray, vn: np.ndarray, keep_v: np.ndarray) -> np.ndarray:
    """|n . (p - mean of p's neighbours)| (m) at each kept vertex: its height off the 1-ring."""
    i = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0]])
    j = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2]])
    total = np.zeros_like(v)
    np.add.at(total, i, v[j])
    count = np.bincount(i, minlength=len(v)).astype(float)
    ring = total / np.maximum(count, 1.0)[:, None]
    off = np.abs(np.sum((v - ring) * vn, axis=1))
    return off[keep_v & (count > 0)]


def height_field(v: np.ndarray, keep_v: np.ndarray, floor_y: float, *, cell: float = 0.002, sigma: float = 0.015):
    """(heights above the floor, the same blurred over `sigma`, in-the-field mask, cell) of the kept
    vertices, on a grid of `cell` m (x, z); the blur is normalised by the field's own mask, so
    its edge is not pulled down, and the mask keeps only cells a whole blur away from the edge."""
    xz, y = v[keep_v][:, [0, 2]], v[keep_v, 1] - floor_y
    lo, hi = xz.min(axis=0), xz.max(axis=0)
    gx, gz = (np.arange(a, b + cell, cell) for a, b in zip(lo, hi))
    h = griddata(xz, y, tuple(np.meshgrid(gx, gz, indexing="ij")), method="linear")
    inside = np.isfinite(h).astype(float)
    s = sigma / cell
    weight = gaussian_filter(inside, s)
    blurred = gaussian_filter(np.nan_to_num(h), s) / np.maximum(weight, 1e-9)
    return h, blurred, (inside > 0) & (weight > 0.99), cell


def measure(v: np.ndarray, f: np.ndarray, *, floor_y: float, spacing: float) -> dict:
    """The table's row for one mesh (metres in, the units of the table out)."""
    n, area = face_normals(v, f)
    centre_y = v[f].mean(axis=1)[:, 1] - floor_y
    top = (n[:, 1] > 0.2) & (centre_y > 2.0 * spacing)
    angles = neighbour_angles(f, n, top)
    keep_v = np.zeros(len(v), bool)
    keep_v[f[top].ravel()] = True
    vn = np.zeros_like(v)
    np.add.at(vn, f.ravel(), np.repeat(n * area[:, None], 3, axis=0))
    vn /= np.maximum(np.linalg.norm(vn, axis=1), 1e-30)[:, None]
    bumps = bump_heights(v, f, vn, keep_v)
    peak = float(v[:, 1].max() - floor_y)
    h, blurred, ok, cell = height_field(v, keep_v, floor_y)
    flank = ok & (blurred > 0.2 * peak) & (blurred < 0.8 * peak)
    ridges = np.abs(h - blurred)[flank]
    gx, gz = np.gradient(blurred, cell)
    slope = np.degrees(np.arctan(np.hypot(gx, gz)[flank]))
    volume = float(np.sum(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]]))) / 6.0)
    return {
        "angle_mean": float(angles.mean()),
        "angle_p95": float(np.percentile(angles, 95)),
        "bump_mean_mm": 1e3 * float(bumps.mean()),
        "bump_p95_mm": 1e3 * float(np.percentile(bumps, 95)),
        "ridge_rms_mm": 1e3 * float(np.sqrt(np.mean(ridges**2))),
        "ridge_p95_mm": 1e3 * float(np.percentile(ridges, 95)),
        "peak_cm": 100.0 * peak,
        "flank_deg": float(np.median(slope)) if slope.size else float("nan"),
        "volume_l": 1e3 * volume,
        "faces": len(f),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("shot", nargs="?", default=str(ROOT / "pipeline" / "shots" / "sand_collapse.toml"))
    p.add_argument("--iters", nargs="+", type=int, default=[1, 2, 4, 8], help="surface.smooth_iters values")
    p.add_argument("--frame", type=int, default=None, help="the frame measured (default: the shot's last)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="shot overrides")
    p.add_argument("--cache", default="/tmp/ridge-cache", help="stage cache root")
    p.add_argument("--device", default="cpu")
    args = p.parse_args(argv)
    shot = load_shot_config(args.shot, args.set)
    run = ShotRun(shot, cache_root=args.cache, quiet=True, publish=False, device=args.device)
    run.run(until="simulate")
    sim = run.entries()["simulate"]
    frame = args.frame or shot.shot.frame_end
    particles = sim.read(sim.frame_path(frame, ParticleFrame.EXT), ParticleFrame.read)
    floor_y = solver_floor(shot)
    group = shot.surface_groups()[0]
    print(
        f"{shot.shot.name}, frame {frame}, {len(particles.x):,} particles, spacing {1e3 * shot.particle_spacing:.1f} mm"
    )
    print(
        "| smooth_iters | neighbour angle mean / p95 (deg) | bump mean / p95 (mm) | ridge RMS / p95 (mm) | peak (cm) | flank (deg) | volume (l) | faces |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for iters in args.iters:
        params = dataclasses.replace(surface_params(shot, group), smooth_iters=iters)
        mesh = surface_particles(particles.x, None, params, device=args.device).mesh
        r = measure(
            np.asarray(mesh.vertices, float), np.asarray(mesh.faces), floor_y=floor_y, spacing=shot.particle_spacing
        )
        print(
            f"| {iters} | {r['angle_mean']:.1f} / {r['angle_p95']:.1f} | {r['bump_mean_mm']:.2f} / {r['bump_p95_mm']:.2f} "
            f"| {r['ridge_rms_mm']:.2f} / {r['ridge_p95_mm']:.2f} "
            f"| {r['peak_cm']:.1f} | {r['flank_deg']:.1f} | {r['volume_l']:.2f} | {r['faces']:,} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
