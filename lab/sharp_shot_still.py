"""A shot's surface frames with and without sharp edges, side by side with their difference:
the README's picture of surface.sharp_edges on a real simulation (snow_smash's snow bed).

    mpmfx run pipeline/shots/snow_smash.toml --until surface --cache /tmp/on
    mpmfx run pipeline/shots/snow_smash.toml --until surface --cache /tmp/off --set surface.sharp_edges=false
    python lab/sharp_shot_still.py /tmp/on/snow_smash /tmp/off/snow_smash --frames 1 13

Each argument is a shot's cache folder; its newest surface entry is read. Every group of a
frame is drawn in one grey, smooth-shaded with area-weighted vertex normals, one key light.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mpmfx.bench.surface_flicker import vertex_normals
from mpmfx.io.frames import SurfaceFrame
from mpmfx.render import import_pyvista

CAMERA = [(0.55, 0.45, 0.75), (0.05, 0.08, 0.05), (0.0, 1.0, 0.0)]
GAIN = 3


def frames_dir(shot_cache: Path) -> Path:
    """The frames folder of the newest surface entry under a shot's cache folder."""
    entries = sorted((shot_cache / "surface").glob("surface-*/frames"), key=lambda p: p.stat().st_mtime)
    if not entries:
        raise SystemExit(f"{shot_cache}: no surface entry; run the shot with --until surface first")
    return entries[-1]


def picture(pv, path: Path, size: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) uint8 picture of every group's mesh in a surface frame (.npz) from CAMERA."""
    frame = SurfaceFrame.read(path)
    plotter = pv.Plotter(off_screen=True, window_size=size, lighting="none")
    plotter.set_background("black")
    plotter.add_light(pv.Light(position=(0.9, 1.2, 0.8), focal_point=(0, 0, 0), intensity=1.0))
    plotter.add_light(pv.Light(position=(-0.6, 0.5, -0.5), focal_point=(0, 0, 0), intensity=0.35))
    for group in frame.groups.values():
        if len(group.vertices):
            v, f = group.vertices.astype(np.float64), group.faces
            mesh = pv.PolyData(v, np.hstack([np.full((len(f), 1), 3), f]).ravel())
            mesh.point_data["Normals"] = vertex_normals(v, f)
            plotter.add_mesh(
                mesh, color="#e8eef4", smooth_shading=True, specular=0.8, specular_power=50, diffuse=0.7, ambient=0.1
            )
    plotter.camera_position = CAMERA
    img = np.asarray(plotter.screenshot(return_img=True))[..., :3]
    plotter.close()
    return img


def main() -> None:
    from PIL import Image, ImageDraw

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sharp", type=Path, help="the shot's cache folder surfaced with sharp edges (the default)")
    ap.add_argument("round", type=Path, help="the same with surface.sharp_edges = false")
    ap.add_argument("--frames", type=int, nargs="+", default=[1, 13])
    ap.add_argument("--out", default="docs/images/surface_sharp_snow_smash.png")
    args = ap.parse_args()
    pv = import_pyvista()
    size = (640, 400)
    rows = []
    for frame in args.frames:
        a, b = (picture(pv, frames_dir(c) / f"{frame:04d}.{SurfaceFrame.EXT}", size) for c in (args.sharp, args.round))
        diff = np.clip(np.abs(a.astype(int) - b.astype(int)).max(axis=2) * GAIN, 0, 255).astype(np.uint8)
        strip = Image.fromarray(np.concatenate([a, b, np.repeat(diff[..., None], 3, axis=2)], axis=1))
        draw = ImageDraw.Draw(strip)
        draw.text((8, 8), f"frame {frame}: sharp edges (the default)", fill=(255, 255, 255))
        draw.text((size[0] + 8, 8), "surface.sharp_edges = false", fill=(255, 255, 255))
        draw.text((2 * size[0] + 8, 8), f"|difference| x{GAIN}", fill=(255, 255, 255))
        rows.append(np.asarray(strip))
    Image.fromarray(np.concatenate(rows, axis=0)).save(args.out)
    print(args.out)


if __name__ == "__main__":
    main()
