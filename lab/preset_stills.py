"""Stills of the material presets: one scene, run once per preset through the whole pipeline.

The scene: a pillar of material (assets/sand_column.obj: 24 cm across, 40 cm tall), leaning 20
degrees and thrown down onto the floor at 3 m/s, in a 1 m box at grid_n 40 (dx 2.5 cm, 8
particles a cell, about 9,200 particles), walls "separate", no damping. Only the material
changes from still to still, so the pictures compare the presets themselves: the jelly bounces
off the floor whole; the snow ladder goes from a pillar that topples in one piece (Soft) through
one whose foot crushes (Mushy) to heaps that crumple lower and lower (Goopy, Wet, Slush); the
sand slumps into a spreading mound; the water collapses and runs out over the floor.

For each preset this writes a shot file into a temporary folder, runs voxelise, simulate,
surface, export and render on it up to the still's frame (`mpmfx.stages.runner.ShotRun` with
publishing off, so nothing lands in renders/ or published/), and renders the frame of `STILLS`
where the material's behaviour reads, with Cycles (640x360, 16 samples, denoised, the preset's
default look from mpmfx/render/looks.py). Tracer is a massless marker: on its own it would hang
still in the air, so its still is the Water scene with a 12 cm ball of tracer seeded inside the
pillar's upper part, which the water carries down as a dye (the yellow seen through the water).

Writes docs/images/preset_<Name>.png (one per preset) and docs/images/presets.png (the labelled
grid). Run from the repository root, with mpmfx installed (`pip install -e .` or setup.sh):

    python lab/preset_stills.py [--cache /tmp/preset-cache] [--only Soft Water] [--out docs/images]

About 3 minutes of wall time on a 2-core CPU from an empty cache (Cycles included); the stage
cache makes a re-run free.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

from mpmfx.mpm.materials import PRESETS
from mpmfx.shotfile import load_shot_config
from mpmfx.stages.runner import ShotRun

ROOT = Path(__file__).resolve().parents[1]

# The shot every preset runs, filled in per preset (str.format).
SCENE = """\
[shot]
name = "preset_{name}"
frame_end = {frame_end}

[domain]
origin = [-0.5, -0.075, -0.5]   # y = -3 dx: the solver's floor is y = 0
size = 1.0
grid_n = 40

[[objects]]
name = "pillar"
mesh = "{pillar}"
material = "{material}"
translate = [0.05, 0.12, 0.0]
rotate = [0.0, 0.0, 20.0]       # leaning: it lands on one edge of its foot
velocity = [0.0, -3.0, 0.0]     # 24 cm across, 40 cm tall: 9.6 by 16 cells
{tracer}
[solver]
damping = 0.0
walls = "separate"
wall_friction = 0.5

[render]
engine = "{engine}"
width = {width}
height = {height}
samples = {samples}
camera_position = [0.66, 0.7, 1.06]
camera_look_at = [-0.06, 0.1, 0.0]
movie = false
"""

# The Tracer still: a ball of dye in the pillar's upper part, carried by the water.
TRACER = """
[[objects]]
name = "dye"
mesh = "{ball}"
material = "Tracer"
translate = [-0.046, 0.383, 0.0]  # on the pillar's axis, 28 cm up
scale = 0.4                       # 12 cm across
velocity = [0.0, -3.0, 0.0]
"""

# The frame of each preset's still (24 fps; frame 1 is the release, the foot lands in frame 2).
STILLS = {
    "Soft": 13,
    "Mushy": 12,
    "Goopy": 8,
    "Wet": 8,
    "Slush": 8,
    "Elastic": 3,
    "Granular": 4,
    "CohesiveGranular": 4,
    "Water": 3,
    "Tracer": 3,
}


def shot_text(name: str, *, engine: str, width: int, height: int, samples: int, frame_end: int) -> str:
    pillar, ball = ((ROOT / "assets" / f).as_posix() for f in ("sand_column.obj", "snowball.obj"))
    material = "Water" if name == "Tracer" else name
    tracer = TRACER.format(ball=ball) if name == "Tracer" else ""
    return SCENE.format(
        name=name,
        pillar=pillar,
        material=material,
        tracer=tracer,
        engine=engine,
        width=width,
        height=height,
        samples=samples,
        frame_end=frame_end,
    )


def still(name: str, folder: Path, *, cache: Path, frame: int, **render) -> Path:
    """Run the scene with preset `name` up to `frame`; the rendered frame's path (in the cache)."""
    path = folder / f"preset_{name}.toml"
    path.write_text(shot_text(name, frame_end=max(frame, 2), **render))
    run = ShotRun(load_shot_config(path), cache_root=cache, quiet=True, publish=False)
    t0 = time.perf_counter()
    run.run(until="render", frames=[frame])
    print(f"{name:<17} frame {frame:>2}  {time.perf_counter() - t0:6.1f} s", flush=True)
    return run.entries()["render"].frame_path(frame, "png")


def font(size: int) -> ImageFont.ImageFont:
    try:
        return ImageFont.truetype("DejaVuSans-Bold.ttf", size)
    except OSError:
        return ImageFont.load_default(size=size)


def montage(stills: dict[str, Path], out: Path, *, columns: int = 5, tile: tuple[int, int] = (384, 216)) -> Path:
    """A grid of the stills, each labelled with its preset's name."""
    rows = -(-len(stills) // columns)
    w, h = tile
    sheet = Image.new("RGB", (columns * w, rows * h), (24, 26, 30))
    draw, f = ImageDraw.Draw(sheet), font(max(16, h // 9))
    for i, (name, path) in enumerate(stills.items()):
        x, y = (i % columns) * w, (i // columns) * h
        sheet.paste(Image.open(path).convert("RGB").resize(tile, Image.LANCZOS), (x, y))
        tw = draw.textlength(name, font=f)
        draw.rectangle([x, y, x + tw + 16, y + f.size + 14], fill=(0, 0, 0))
        draw.text((x + 8, y + 6), name, font=f, fill=(255, 255, 255))
    sheet.save(out, optimize=True)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cache", default="/tmp/preset-cache", help="stage cache root")
    p.add_argument("--out", default=str(ROOT / "docs" / "images"), help="folder for the PNGs")
    p.add_argument("--only", nargs="*", default=None, choices=list(STILLS), help="these presets only (no montage)")
    p.add_argument("--engine", default="cycles", choices=("cycles", "preview"))
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=360)
    p.add_argument("--samples", type=int, default=16)
    p.add_argument("--frame", type=int, default=None, help="this frame for every preset (default: STILLS)")
    args = p.parse_args(argv)
    assert set(STILLS) == set(PRESETS), "a preset without a still (or a still without a preset)"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    names = args.only or list(STILLS)
    render = {"engine": args.engine, "width": args.width, "height": args.height, "samples": args.samples}
    made = {}
    with tempfile.TemporaryDirectory(prefix="preset_stills_") as tmp:
        for name in names:
            frame = args.frame or STILLS[name]
            src = still(name, Path(tmp), cache=Path(args.cache), frame=frame, **render)
            made[name] = out / f"preset_{name}.png"
            Image.open(src).convert("RGB").save(made[name], optimize=True)
    if args.only is None:
        print(montage(made, out / "presets.png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
