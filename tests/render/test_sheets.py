"""Contact and wedge sheets: distinct frames whatever their number, legible, labels readable."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from mpmfx.render.sheets import contact_sheet, label
from mpmfx.wedge import write_sheets

# One clearly different colour per frame (none of them black, none grey).
COLOURS = [(230, 40, 40), (40, 200, 40), (40, 80, 230), (230, 200, 40), (200, 40, 200), (40, 200, 220), (250, 130, 20)]


def _frames(folder, n: int, size=(160, 120)) -> dict[int, object]:
    out = {}
    for i in range(n):
        path = folder / f"{i + 1:04d}.png"
        Image.new("RGB", size, COLOURS[i]).save(path)
        out[i + 1] = path
    return out


def _shown(sheet: np.ndarray, n: int) -> dict[int, float]:
    """Frame -> fraction of the sheet in that frame's colour (labels blur a little of it)."""
    px = sheet.reshape(-1, 3).astype(int)
    return {
        i + 1: float((np.abs(px - COLOURS[i]).max(axis=1) < 12).mean())
        for i in range(n)
        if (np.abs(px - COLOURS[i]).max(axis=1) < 12).mean() > 0.02
    }


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 7])
def test_contact_sheet_shows_distinct_frames_and_no_empty_tile(tmp_path, n):
    frames = _frames(tmp_path, n)
    sheet = np.asarray(Image.open(contact_sheet(frames, tmp_path / "contact.png")).convert("RGB"))
    shown = _shown(sheet, n)
    assert len(shown) == min(n, 4)  # each tile a different frame
    assert 1 in shown and n in shown  # first and last
    black = (sheet.max(axis=2) < 20).mean()
    assert black < 0.01, f"{black:.0%} of the sheet is black (an empty tile)"
    assert min(shown.values()) > 0.5 / min(n, 4)  # every tile a fair share of the sheet
    assert 960 <= sheet.shape[1] <= 1920


@pytest.mark.parametrize("sky", ["#ffffff", "#e8dcc0", "#8fb4d8", "#000000"])
def test_labels_read_on_any_sky(sky):
    image = np.asarray(Image.new("RGB", (480, 270), sky))
    out = label(image, "radius_scale=1.2  frame 12")
    changed = np.any(out != image, axis=2)
    assert changed.any()
    lum = out[changed].astype(float) @ [0.2126, 0.7152, 0.0722]
    box, text = np.median(lum), np.percentile(lum, 99)
    assert box < 100 and text - box > 150, (sky, box, text)
    # the box is translucent: the sky still tints it
    if sky != "#000000":
        assert np.median(out[changed].astype(int), axis=0).tolist() != [0, 0, 0]


def test_wedge_sheets_are_legible(tmp_path):
    tiles = []
    for v in range(3):
        (tmp_path / f"v{v}").mkdir()
        tiles.append((f"smooth_iters={v}", _frames(tmp_path / f"v{v}", 6)))
    made = write_sheets(tmp_path / "wedge", tiles, list(range(1, 7)), fps=24, movie=False)
    contact = np.asarray(Image.open(made["contact"]).convert("RGB"))
    sheet = np.asarray(Image.open(made["sheets"] / "0003.png").convert("RGB"))
    assert contact.shape[1] >= 960 and sheet.shape[1] >= 960
    # contact: a row per variant, four distinct frames in each, first and last among them
    shown = _shown(contact, 6)
    assert sorted(shown) == [1, 3, 4, 6]
