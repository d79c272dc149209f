"""The README's figure of surface.sharp_edges: the bench's random box cut by two planes, "round"
(the surface stage's setting with surface.sharp_edges = false) against "fine" (the setting, with
sharp edges). Left: the plane z = 0,
at the middle of the edge x = +0.3, y = +0.2 m. Right: the plane z = +0.25 - h, a spacing
under the top face, at the corner above that edge. Dots: the particles within h / 2 of the
plane; the vertex error of each mesh (mean and max over the whole box) in the legend.

    python lab/sharp_still.py [--count 100000] [--seed 2] [--out docs/images/surface_sharp.png]
"""

from __future__ import annotations

import argparse

import numpy as np

from mpmfx.bench.surface_cases import BOX_HALF, OURS, sample_shape, shape_sdf
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles


def surface(x: np.ndarray, h: float, label: str):
    setting = dict(OURS[label])
    params = SurfaceParams(
        PARTICLE_RADIUS_PER_SPACING * h, voxel_size=setting.pop("voxel_h") * h, dense_output=False, **setting
    )
    return surface_particles(x, None, params, device="cpu").mesh


def section(mesh, z: float) -> np.ndarray:
    """(k, 2, 2) segments of the mesh's cut by the plane at height z, (x, y) in metres."""
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    return trimesh.intersections.mesh_plane(tm, [0, 0, 1], [0, 0, z])[:, :, :2]


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--out", default="docs/images/surface_sharp.png")
    args = ap.parse_args()
    sdf = shape_sdf("box")[0]
    x, h = sample_shape("box", args.count, "random", seed=args.seed)
    meshes = {label: surface(x, h, label) for label in ("round", "fine")}
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.4))
    for ax, (z, where) in zip(
        axes, ((0.0, "the middle of an edge (z = 0)"), (BOX_HALF[2] - h, "a corner, one spacing under the top face"))
    ):
        lo, hi = BOX_HALF[:2] - 5 * h, BOX_HALF[:2] + 1.5 * h
        near = (np.abs(x[:, 2] - z) < 0.5 * h) & np.all(x[:, :2] > lo - h, axis=1)
        ax.scatter(x[near, 0], x[near, 1], s=14, c="0.75", zorder=1)
        ax.plot(
            [lo[0], BOX_HALF[0], BOX_HALF[0]], [BOX_HALF[1], BOX_HALF[1], lo[1]], c="k", lw=1, zorder=2, label="the box"
        )
        for label, style, colour in (("round", "--", "tab:red"), ("fine", "-", "tab:blue")):
            mesh = meshes[label]
            err = np.abs(sdf(mesh.vertices.astype(np.float64))) / h
            what = '"fine" (shots\' default)' if label == "fine" else '"round" (surface.sharp_edges = false)'
            ax.add_collection(
                LineCollection(
                    section(mesh, z),
                    colors=colour,
                    linestyles=style,
                    lw=2,
                    zorder=3,
                    label=f"{what}: vertex mean {err.mean():.3f} h, max {err.max():.2f} h",
                )
            )
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{where}; h = {h * 1000:.1f} mm", fontsize=10)
        ax.legend(loc="lower left", fontsize=8)
    fig.suptitle(
        f"The bench's box, {len(x)} uniformly random particles (seed {args.seed}), cut beside an edge: "
        "sharp edges put the faces' planes back where the sample thins",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(args.out)


if __name__ == "__main__":
    main()
