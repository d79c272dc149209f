"""Sheets: several frames in one picture (a shot's contact sheet, a wedge's sheets), each tile
labelled so that the label reads on any sky.

Images are (h, w, 3) uint8 arrays, sizes in pixels. Every sheet is at least SHEET_MIN_WIDTH
wide (small renders are scaled up, so the labels stay legible) and at most SHEET_MAX_WIDTH.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from mpmfx.cache import atomic_path

SHEET_MIN_WIDTH = 960  # px: a sheet narrower than this is scaled up (legible tiles and labels)
SHEET_MAX_WIDTH = 1920  # px: a sheet wider than this is scaled down
LABEL_BOX = (16, 18, 24, 170)  # RGBA: a dark translucent box, so light text reads on sky or snow
LABEL_TEXT = (255, 255, 255, 255)
MISSING_TILE = "#404040"


def evenly_spaced(items: list, count: int) -> list:
    """Up to `count` distinct items, the first and the last among them, evenly spaced."""
    n = min(count, len(items))
    if n <= 1:
        return items[:n]
    return [items[round(i * (len(items) - 1) / (n - 1))] for i in range(n)]


def columns_for(count: int) -> int:
    """Tiles per row for `count` tiles: one row up to three, then two rows of two, then rows of
    three; no row but the last has a gap."""
    if count <= 3:
        return max(count, 1)
    return 2 if count == 4 else 3


def read_tile(path: Path | None) -> np.ndarray | None:
    """The RGB image at `path`, or None where there is none."""
    if path is None or not Path(path).is_file():
        return None
    return np.asarray(Image.open(path).convert("RGB"))


def label(image: np.ndarray, text: str) -> np.ndarray:
    """`image` with `text` in its lower left corner, light on a dark translucent box (the sky
    shows through the box, and the text reads on white snow and on a bright sky alike)."""
    if not text:
        return image
    img = Image.fromarray(image).convert("RGBA")
    overlay = Image.new("RGBA", img.size, (0, 0, 0, 0))
    draw = ImageDraw.Draw(overlay)
    font = ImageFont.load_default(size=max(12, img.height // 18))
    pad = max(4, img.height // 80)
    box = draw.textbbox((0, 0), text, font=font)
    top = img.height - (box[3] - box[1]) - 3 * pad
    draw.rectangle((pad, top, pad + box[2] - box[0] + 2 * pad, img.height - pad), fill=LABEL_BOX)
    draw.text((2 * pad - box[0], top + pad - box[1]), text, fill=LABEL_TEXT, font=font)
    return np.asarray(Image.alpha_composite(img, overlay).convert("RGB"))


def grid(images: list[np.ndarray | None], cols: int, labels: list[str] | None = None) -> np.ndarray:
    """The images in rows of `cols` (None: a grey 'missing' tile), all at the first one's size,
    scaled so the sheet is SHEET_MIN_WIDTH..SHEET_MAX_WIDTH wide, each with its label (`label`,
    drawn at the tile's final size); sizes even (H.264)."""
    first = next((a for a in images if a is not None), np.zeros((540, 960, 3), np.uint8))
    h, w = first.shape[:2]
    width = min(max(cols * w, SHEET_MIN_WIDTH), SHEET_MAX_WIDTH)
    tw = width // cols
    th = max(2, round(h * tw / w))
    texts = labels or [""] * len(images)
    tiles = [label(_fit(a, (tw, th)), t if a is not None else f"{t}  missing".strip()) for a, t in zip(images, texts)]
    blank = np.zeros((th, tw, 3), np.uint8)
    rows = []
    for i in range(0, len(tiles), cols):
        row = tiles[i : i + cols]
        rows.append(np.concatenate([*row, *[blank] * (cols - len(row))], axis=1))
    sheet = np.concatenate(rows, axis=0)
    return sheet[: sheet.shape[0] // 2 * 2, : sheet.shape[1] // 2 * 2]


def _fit(image: np.ndarray | None, size: tuple[int, int]) -> np.ndarray:
    """`image` resized to size (w, h); None: a grey tile."""
    if image is None:
        return np.asarray(Image.new("RGB", size, MISSING_TILE))
    if image.shape[1::-1] == size:
        return image
    return np.asarray(Image.fromarray(image).resize(size, Image.LANCZOS))


def save(image: np.ndarray, path: Path) -> Path:
    """Write a PNG through a temp name (`cache.atomic_path`): complete or absent, and a full
    disk is said with the path and the fix."""
    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
    return path


def contact_sheet(frames: dict[int, Path], path: Path, *, count: int = 4) -> Path:
    """Up to `count` distinct, evenly spaced frames of {frame: PNG} in one picture, each
    labelled with its frame number; read left to right, top to bottom. Fewer frames than
    `count` give fewer tiles (one frame: one tile), never a repeated frame or an empty tile."""
    picks = evenly_spaced(sorted(frames), count)
    if not picks:
        raise ValueError(f"{path}: a contact sheet needs at least one frame")
    tiles = [read_tile(frames[f]) for f in picks]
    return save(grid(tiles, columns_for(len(tiles)), [f"frame {f}" for f in picks]), path)
