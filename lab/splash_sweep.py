"""Our surfacer isotropic and anisotropic on every frame of a water_dam run (the README's sweep).

Reads a simulate stage's frames (e.g. after `mpmfx run pipeline/shots/water_dam.toml --until
simulate --device cpu --cache DIR`, they lie under DIR/water_dam/simulate/simulate-*/frames)
and prints, per frame and radius_scale (the shot's 1.2 and the default 1.0), pieces, pieces of
at least 8 h^3, holes, open edges, volume over n h^3 and seconds, as the splash bench measures
them (mpmfx.bench.surface_splash).

    python lab/splash_sweep.py FRAMES_DIR [--frames 9 10 12 13 15 16 18] [--device cpu]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from mpmfx.bench.surface_splash import SPLASH_SHOT, _row, splash_params
from mpmfx.shotfile import load_shot_config
from mpmfx.surface import surface_particles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("frames_dir")
    ap.add_argument("--frames", type=int, nargs="+", default=[9, 10, 12, 13, 15, 16, 18])
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    h = load_shot_config(SPLASH_SHOT).particle_spacing
    print("frame radius_scale method       seconds pieces >=8h3 holes open vol/nh3")
    for frame in args.frames:
        x = np.load(Path(args.frames_dir) / f"{frame:04d}.npz")["x"]
        for scale in (1.2, 1.0):
            for aniso in (False, True):
                params = dataclasses.replace(splash_params(h, anisotropic=aniso), radius_scale=scale)
                t0 = time.perf_counter()
                mesh = surface_particles(x, None, params, device=args.device).mesh
                r = _row("", x, h, time.perf_counter() - t0, mesh.vertices, mesh.faces, args.device, "")
                print(
                    f"{frame:5d} {scale:12g} {'anisotropic' if aniso else 'isotropic':12} {r['seconds']:7.1f} "
                    f"{r['components']:6d} {r['pieces_big']:5d} {r['holes']:5d} {r['open_edges']:4d} "
                    f"{r['volume_ratio']:7.3f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
