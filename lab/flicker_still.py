"""Flicker strip: two consecutive frames of a slowly moving block and their difference image.

The bench's moving block (mpmfx.bench.surface_flicker: uniformly random particles gliding 0.1 h a
frame and creeping 0.01 h), frames 0 and 1 surfaced on their own, each mesh moved back by the
body's motion and drawn from the same camera with a glossy material (a key light grazing the
top face, so a normal change shows as a highlight change). A surfacer without flicker gives
two equal pictures and a black difference. Rows: ours at the shot setting ("fine"), then
splashsurf where installed. The difference is |frame 1 - frame 0| over RGB, times GAIN.

    python lab/flicker_still.py [--count 20000] [--out docs/images/surface_flicker.png]
"""

from __future__ import annotations

import argparse

import numpy as np

from mpmfx.bench.surface_flicker import RENDER_SIZE, flicker_run, moving_frames, ours, peer, render
from mpmfx.bench.surface_peers import peer_missing
from mpmfx.render import import_pyvista

GAIN = 4


def main() -> None:
    from PIL import Image, ImageDraw

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=20_000)
    ap.add_argument("--out", default="docs/images/surface_flicker.png")
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    pv = import_pyvista()
    xs, h, step = moving_frames(args.count, frames=2)
    methods = [("mpmfx fine", ours("fine", h, args.device))]
    if peer_missing("splashsurf") is None:
        methods.append(("splashsurf", peer("splashsurf", h)))
    size = RENDER_SIZE
    rows = []
    for name, run in methods:
        stats, meshes = flicker_run(run, xs, h, step)
        a, b = (render(pv, v, f, size) for v, f in meshes)
        diff = np.clip(np.abs(b.astype(int) - a.astype(int)).max(axis=2) * GAIN, 0, 255).astype(np.uint8)
        strip = Image.fromarray(np.concatenate([a, b, np.repeat(diff[..., None], 3, axis=2)], axis=1))
        draw = ImageDraw.Draw(strip)
        s = stats[1]
        draw.text((8, 8), f"{name}: frame 0", fill=(0, 0, 0))
        draw.text((size[0] + 8, 8), "frame 1 (moved back)", fill=(0, 0, 0))
        draw.text(
            (2 * size[0] + 8, 8),
            f"|difference| x{GAIN}: normal turn {s['normal_turn_deg']:.1f} deg faces, "
            f"p99 {s['edge_turn_p99_deg']:.0f} deg edges",
            fill=(255, 255, 255),
        )
        rows.append(np.asarray(strip))
        print(name, {k: round(v, 4) for k, v in s.items() if isinstance(v, float)})
    Image.fromarray(np.concatenate(rows, axis=0)).save(args.out)
    print(f"wrote {args.out} ({len(xs[0])} particles, h = {h:.4g} m)")


if __name__ == "__main__":
    main()
