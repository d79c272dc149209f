"""Snow glints at two render widths: the same patch of snow, cropped from a small and a large render.

Runs a preset still's scene (`lab/preset_stills.py`, Mushy by default, frame 12) through the
pipeline at the smallest width, then renders the same frame again at each width with Cycles
restricted to one region of the frame (a border crop: only those pixels are rendered, so a
1920-px frame costs what its crop does). In each crop the glints are found as pixels brighter
than the median of their 7 x 7 neighbourhood by more than `--contrast` levels (8-bit sRGB
luminance), grouped into connected spots, and measured: how many, and how large (pixels; the
diameter of a disc of the same area). A glint sized in pixels of the render keeps its size in
pixels from width to width; one sized in metres grows with the width (`--glint-mm 4`: the
glints a fixed 4 mm across at every width, for comparison).

    python lab/glint_scale.py [--widths 480 1920] [--preset Mushy] [--frame 12] [--samples 16] [--glint-mm 4]

Prints one table and writes /tmp/glint_scale.png (the crops side by side, each scaled to the
largest; `--out` moves it). About a minute of Cycles on a 2-core CPU for the default widths,
after the scene's simulation (cached under `--cache`).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image
from preset_stills import still
from scipy import ndimage

# Cycles in Blender's own process (bpy and pxr must not meet): the render stage's job, cropped.
CHILD = """
import json, sys
import bpy
from mpmfx.render import cycles_job
job = json.loads(open(sys.argv[1]).read())
x0, x1, y0, y1 = job.pop("border")
fixed = job.pop("glint_m")
if fixed:  # glints a fixed size in metres: a pixel "covers" half of it wherever the camera is
    cycles_job.metres_per_pixel = lambda camera, width: fixed / 2.0
cycles_job.build_scene(job)
r = bpy.context.scene.render
r.use_border, r.use_crop_to_border = True, True
r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = x0, x1, y0, y1
cycles_job.render_frames(job)
"""


def glints(path: Path, contrast: float) -> dict:
    """Count and size (pixels) of the bright spots in the image at `path`."""
    rgb = np.asarray(Image.open(path).convert("RGB"), float)
    lum = rgb @ np.array([0.2126, 0.7152, 0.0722])
    spots, n = ndimage.label(lum - ndimage.median_filter(lum, size=7) > contrast)
    area = np.bincount(spots.ravel())[1:] if n else np.zeros(1)
    return {
        "count": int(n),
        "area_mean": float(area.mean()),
        "area_p90": float(np.percentile(area, 90)),
        "diameter": float(2.0 * np.sqrt(area.mean() / np.pi)),
        "pixels": lum.shape[1] * lum.shape[0],
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--widths", nargs="+", type=int, default=[480, 1920])
    p.add_argument("--preset", default="Mushy")
    p.add_argument("--frame", type=int, default=12)
    p.add_argument("--samples", type=int, default=16)
    p.add_argument("--border", nargs=4, type=float, default=[0.30, 0.55, 0.40, 0.70], metavar=("X0", "X1", "Y0", "Y1"))
    p.add_argument("--contrast", type=float, default=12.0, help="levels over the local median that make a glint")
    p.add_argument(
        "--glint-mm", type=float, default=0.0, help="glints this many mm across at every width (0: two pixels)"
    )
    p.add_argument("--cache", default="/tmp/preset-cache", help="stage cache root")
    p.add_argument("--out", default="/tmp/glint_scale.png")
    args = p.parse_args(argv)
    widths = sorted(args.widths)
    crops = {}
    with tempfile.TemporaryDirectory(prefix="glint_scale_") as tmp:
        tmp = Path(tmp)
        frame = still(
            args.preset,
            tmp,
            cache=Path(args.cache),
            frame=args.frame,
            engine="cycles",
            width=widths[0],
            height=widths[0] * 9 // 16,
            samples=args.samples,
        )
        job = json.loads(next(frame.parents[1].glob("*_job.json")).read_text())
        for w in widths:
            crops[w] = tmp / f"crop_{w}.png"
            spec = {**job, "width": w, "height": w * 9 // 16, "outputs": [str(crops[w])], "blend": None}
            spec |= {"frames": [args.frame], "label": "", "border": args.border, "glint_m": 1e-3 * args.glint_mm}
            (tmp / f"job_{w}.json").write_text(json.dumps(spec))
            subprocess.run([sys.executable, "-c", CHILD, str(tmp / f"job_{w}.json")], check=True, capture_output=True)
        sized = f"glints {args.glint_mm} mm" if args.glint_mm else "glints two pixels"
        print(f"{args.preset}, frame {args.frame}, {args.samples} samples, crop {args.border} of the frame, {sized}")
        print("| width (px) | crop (px) | glints | per 10k px | mean area (px) | p90 area (px) | diameter (px) |")
        print("|---|---|---|---|---|---|---|")
        for w in widths:
            g = glints(crops[w], args.contrast)
            size = Image.open(crops[w]).size
            print(
                f"| {w} | {size[0]}x{size[1]} | {g['count']} | {1e4 * g['count'] / g['pixels']:.1f} "
                f"| {g['area_mean']:.1f} | {g['area_p90']:.1f} | {g['diameter']:.1f} |"
            )
        big = Image.open(crops[widths[-1]]).size
        sheet = Image.new("RGB", (big[0] * len(widths), big[1]))
        for i, w in enumerate(widths):
            sheet.paste(Image.open(crops[w]).convert("RGB").resize(big, Image.NEAREST), (i * big[0], 0))
        sheet.save(args.out, optimize=True)
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
