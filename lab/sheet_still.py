"""Still of the thin-sheet case, isotropic against anisotropic kernels (the README's figure).

A disc one particle spacing thick, uniformly random particles (a splash sheet), surfaced at the
surface stage's setting ("fine") without and with `SurfaceParams.anisotropic`, drawn side by
side with PyVista, holes counted in the titles.

    python lab/sheet_still.py [--count 10000] [--out docs/images/surface_sheet.png] [--device cpu]
"""

from __future__ import annotations

import argparse

import numpy as np

from mpmfx.bench.surface_cases import OURS, sample_sheet, sheet_stats
from mpmfx.render import import_pyvista
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=10_000)
    ap.add_argument("--out", default="docs/images/surface_sheet.png")
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    pv = import_pyvista()
    x, h = sample_sheet(args.count, "random")
    setting = dict(OURS["fine"])
    voxel = setting.pop("voxel_h") * h
    plotter = pv.Plotter(shape=(1, 2), off_screen=True, window_size=(1600, 800), border=False)
    for col, aniso in enumerate((False, True)):
        params = SurfaceParams(
            PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False, anisotropic=aniso, **setting
        )
        mesh = surface_particles(x, None, params, device=args.device).mesh
        stats = sheet_stats(mesh.vertices, mesh.faces, h)
        faces = np.hstack([np.full((len(mesh.faces), 1), 3), mesh.faces]).ravel()
        plotter.subplot(0, col)
        plotter.add_mesh(
            pv.PolyData(mesh.vertices.astype(np.float64), faces), color="#5fa8d3", smooth_shading=True, specular=0.4
        )
        kind = "anisotropic (Yu & Turk)" if aniso else "isotropic"
        plotter.add_text(
            f"{kind}: {stats['components']} piece, {stats['holes']} holes, thickness "
            f"{1 + stats['thickness_err']:.2f} h",
            font_size=12,
        )
        plotter.camera_position = [(0.42, -0.62, 0.52), (0.0, 0.02, 0.0), (0.0, 0.0, 1.0)]
        print(kind, stats)
    plotter.screenshot(args.out)
    print(f"wrote {args.out} ({len(x)} particles, h = {h:.4g} m)")


if __name__ == "__main__":
    main()
