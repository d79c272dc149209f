"""Still of the water_dam splash frame (the bench's asset), isotropic against anisotropic kernels.

The surge climbing the far wall (mpmfx.bench.surface_splash: frame SPLASH_FRAME of the shot as
shipped), surfaced at the shot's setting without and with `SurfaceParams.anisotropic`, drawn
side by side with PyVista, seen from inside the tank towards the far wall; pieces and holes in
the titles.

    python lab/splash_still.py [--out docs/images/surface_splash.png] [--device cpu]
"""

from __future__ import annotations

import argparse

import numpy as np

from mpmfx.bench.surface_cases import sheet_stats
from mpmfx.bench.surface_splash import SPLASH_FRAME, load_splash, splash_params
from mpmfx.render import import_pyvista
from mpmfx.surface import surface_particles

CAMERA = [(-1.1, 1.0, -1.3), (0.1, 0.1, 0.0), (0.0, 1.0, 0.0)]
"""Camera (position, focus, up; m): high over the tank's near corner, the whole body of water and the far wall (x = +0.46) in view."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/images/surface_splash.png")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--asset", default=None, help="another splash asset (.npz, write_splash_asset)")
    args = ap.parse_args()
    pv = import_pyvista()
    x, h = load_splash(args.asset) if args.asset else load_splash()
    plotter = pv.Plotter(shape=(1, 2), off_screen=True, window_size=(1600, 800), border=False)
    for col, aniso in enumerate((False, True)):
        mesh = surface_particles(x, None, splash_params(h, anisotropic=aniso), device=args.device).mesh
        stats = sheet_stats(mesh.vertices, mesh.faces, h)
        faces = np.hstack([np.full((len(mesh.faces), 1), 3), mesh.faces]).ravel()
        plotter.subplot(0, col)
        plotter.add_mesh(
            pv.PolyData(mesh.vertices.astype(np.float64), faces), color="#5fa8d3", smooth_shading=True, specular=0.4
        )
        kind = "anisotropic (Yu & Turk)" if aniso else "isotropic"
        plotter.add_text(
            f"water_dam frame {SPLASH_FRAME}, {kind}: {stats['components']} piece(s), {stats['holes']} holes",
            font_size=11,
        )
        plotter.camera_position = CAMERA
        print(kind, stats)
    plotter.screenshot(args.out)
    print(f"wrote {args.out} ({len(x)} particles, h = {h:.4g} m)")


if __name__ == "__main__":
    main()
