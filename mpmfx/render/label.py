"""The label burned into a frame (which shot, which --set variant, which frame): light text on a
dark box, so it reads on any sky, wrapped to the frame's width, so it is never clipped.

PIL only: the preview renderer and the Blender child (Cycles) both call it on the PNG they wrote.
"""

from __future__ import annotations

from pathlib import Path

from PIL import Image, ImageDraw, ImageFont


def _wrap(draw, text: str, font, width: int) -> list[str]:
    """`text` in lines no wider than `width` px, broken at spaces (a word wider than that alone)."""
    lines: list[str] = []
    for word in text.split():
        if lines and draw.textlength(f"{lines[-1]} {word}", font=font) <= width:
            lines[-1] = f"{lines[-1]} {word}"
        else:
            lines.append(word)
    return lines


def burn_label(path: str | Path, text: str) -> None:
    """Draw `text` in the top-left corner of the PNG at `path`, in place: white on a box of
    80 % black, the font sized to the frame (a 30th of its height, at least 12 px; 8 px on a thumbnail). The box
    takes at most the top third of the frame: on a thumbnail too small for the whole text, its
    last line ends in '...'."""
    if not text.strip():
        return
    img = Image.open(path).convert("RGB")
    draw = ImageDraw.Draw(img, "RGBA")
    size = max(12, img.height // 30) if img.height >= 240 else max(8, img.height // 8)  # a thumbnail's own
    font = ImageFont.load_default(size=size)
    pad = max(3, size // 3)
    lines = _wrap(draw, text, font, img.width - 4 * pad)
    step = size + pad // 2
    fit = max(1, (img.height // 3 - 2 * pad) // step)
    if len(lines) > fit:
        lines = lines[:fit]
        while lines[-1] and draw.textlength(lines[-1] + " ...", font=font) > img.width - 4 * pad:
            lines[-1] = lines[-1][:-1]
        lines[-1] += " ..."
    width = max(draw.textlength(line, font=font) for line in lines)
    draw.rectangle((0, 0, min(img.width, width + 4 * pad), len(lines) * step + 2 * pad), fill=(0, 0, 0, 204))
    for i, line in enumerate(lines):
        draw.text((2 * pad, pad + i * step), line, fill=(255, 255, 255), font=font)
    img.save(path, format="PNG")
