"""Still of sharp edges on water, where a narrow face's votes come and go along an edge.

water_dam's splash frame (mpmfx.bench.surface_splash) surfaced at the shot's setting (round:
`surface.sharp_edges = "auto"` leaves fluids so), and with sharp edges forced on as each cell
decided them alone (SHARP["spread"] = 0: ledges) and as shipped (each cell weighed by the
decisions around it), seen from outside the tank under the floor's edge along the wall at
x = -0.46 m, where the water is shallow; the last panel colours each vertex of the shipped
sharpened mesh by how far it lies from the round one (in particle spacings h).

    python lab/ledge_still.py [--out docs/images/surface_water_ledges.png] [--device cpu]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from mpmfx.bench.surface_splash import load_splash, splash_params
from mpmfx.render import import_pyvista
from mpmfx.surface import sharpen, surface_particles

CAMERA = [(-1.2, -0.25, -0.5), (-0.45, 0.0, -0.1), (0.0, 1.0, 0.0)]
"""Camera (position, focus, up; m): outside the tank, a little under its floor, along the wall x = -0.46."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/images/surface_water_ledges.png")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--camera", default=None, help="position,focus as 6 numbers (m): another view")
    args = ap.parse_args()
    camera = CAMERA
    if args.camera:
        c = [float(t) for t in args.camera.split(",")]
        camera = [tuple(c[:3]), tuple(c[3:6]), (0.0, 1.0, 0.0)]
    pv = import_pyvista()
    x, h = load_splash()
    params = splash_params(h, anisotropic=False)
    shipped = sharpen.SHARP["spread"]

    def sharpened(spread: int):
        sharpen.SHARP["spread"] = spread
        try:
            return surface_particles(x, None, dataclasses.replace(params, sharp_edges=True), device=args.device).mesh
        finally:
            sharpen.SHARP["spread"] = shipped

    meshes = [surface_particles(x, None, params, device=args.device).mesh, sharpened(0), sharpened(shipped)]
    moved = cKDTree(meshes[0].vertices).query(meshes[2].vertices)[0] / h
    plotter = pv.Plotter(shape=(2, 2), off_screen=True, window_size=(1600, 1000), border=False)
    panels = [
        (meshes[0], None, "round (the shot's setting)"),
        (meshes[1], None, "sharp, each cell alone: ledges"),
        (meshes[2], None, f"sharp, as shipped (spread {shipped})"),
        (meshes[2], moved, f"moved (h): {np.mean(moved > 0.05):.1%} of the vertices over 0.05 h"),
    ]
    for i, (mesh, scalars, title) in enumerate(panels):
        plotter.subplot(i // 2, i % 2)
        poly = pv.PolyData(
            mesh.vertices.astype(np.float64), np.hstack([np.full((len(mesh.faces), 1), 3), mesh.faces]).ravel()
        )
        if scalars is None:
            plotter.add_mesh(poly, color="#5fa8d3", smooth_shading=True, specular=0.4)
        else:
            poly["moved"] = scalars
            plotter.add_mesh(
                poly,
                scalars="moved",
                clim=[0.0, 0.6],
                smooth_shading=True,
                scalar_bar_args={"title": "moved (h)", "n_labels": 4},
            )
        plotter.add_text(title, font_size=11)
        plotter.camera_position = camera
        plotter.camera.view_angle = 25.0
    plotter.screenshot(args.out)
    print(args.out, f"{np.mean(moved > 0.05):.3f} of vertices moved > 0.05 h, max {moved.max():.2f} h")


if __name__ == "__main__":
    main()
