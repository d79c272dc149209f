"""Cross-section of the bench's box at one edge, with and without the smoothing's edge handling
(the README's figure; mpmfx.surface.edges, smooth.edge_flow_step).

The box's mesh at "fine" (the surface stage's setting) is cut by the plane z = 0 near the edge
at x = +0.3, y = +0.2 m. Solid: the shipped surface; dashed: the edge gate shut (the flow rounds
every edge, as before the ninth session). Left: a lattice (a freshly voxelised body), whose
edge the limit keeps. Right: random samples, where the limit lets the flow smooth the edge as
before, but pits along it are filled (tenth session). Dots: the particles within h / 2 of the
plane (a lattice's two layers at +-h / 2 coincide).

    python scripts/edge_still.py [--count 20000] [--out renders/readme/surface_edge.png]
"""
from __future__ import annotations

import argparse

import numpy as np

from mpmfx.bench.surface_cases import BOX_HALF, OURS, sample_shape, shape_sdf, surface_error
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles
from mpmfx.surface import edges


def section(mesh) -> np.ndarray:
    """(k, 2, 2) segments of the mesh's cut by z = 0, (x, y) in metres."""
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    return trimesh.intersections.mesh_plane(tm, [0, 0, 1], [0, 0, 0])[:, :, :2]


def surface(x: np.ndarray, h: float, *, gate: bool):
    setting = dict(OURS["fine"])
    params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=setting.pop("voxel_h") * h, dense_output=False,
                           **setting)
    kept = edges.EDGE_CURVATURE
    if not gate:
        edges.EDGE_CURVATURE = (1e30, 2e30)  # no curvature opens the gate: the limit is 0.5 r everywhere, no pit is filled
    try:
        return surface_particles(x, None, params, device="cpu").mesh
    finally:
        edges.EDGE_CURVATURE = kept


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=20_000)
    ap.add_argument("--out", default="renders/readme/surface_edge.png")
    args = ap.parse_args()
    sdf = shape_sdf("box")[0]
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.4))
    for ax, sampling in zip(axes, ("lattice", "random")):
        x, h = sample_shape("box", args.count, sampling)
        lo = BOX_HALF[:2] - 5 * h
        hi = BOX_HALF[:2] + 1.5 * h
        near = (np.abs(x[:, 2]) < 0.51 * h) & np.all(x[:, :2] > lo - h, axis=1)
        ax.scatter(x[near, 0], x[near, 1], s=14, c="0.75", zorder=1)
        ax.plot([lo[0], BOX_HALF[0], BOX_HALF[0]], [BOX_HALF[1], BOX_HALF[1], lo[1]], c="k", lw=1, zorder=2,
                label="the box")
        for gate, style, colour in ((False, "--", "tab:red"), (True, "-", "tab:blue")):
            mesh = surface(x, h, gate=gate)
            err = surface_error(mesh.vertices, mesh.faces, sdf) / h
            what = "edge limit, pits filled (shipped)" if gate else "flow rounds the edge (before)"
            ax.add_collection(LineCollection(section(mesh), colors=colour, linestyles=style, lw=2, zorder=3,
                                             label=f"{what}: surface error {err:.4f} h"))
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{sampling} samples, {len(x)} particles, \"fine\", h = {h * 1000:.1f} mm")
        ax.legend(loc="lower left", fontsize=8)
    fig.suptitle("The bench's box cut at z = 0 beside one edge: the smoothing moves an edge inward only as far "
                 "as its samples' noise, and fills pits along it", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(args.out)


if __name__ == "__main__":
    main()
