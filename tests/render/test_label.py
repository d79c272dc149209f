"""A variant's label on a frame reads on any sky and is never clipped."""

from __future__ import annotations

import numpy as np
from PIL import Image

from mpmfx.render.label import burn_label


def test_a_long_label_on_a_beige_sky_is_light_on_dark_and_wraps_inside_the_frame(tmp_path):
    path = tmp_path / "0001.png"
    sky = (222, 208, 180)  # the beige of a low sun's sky, where grey text disappeared
    Image.new("RGB", (480, 270), sky).save(path)
    label = "jelly_splash  --set surface.radius_scale=1.3  --set objects.0.overrides.youngs_modulus=3000  frame 7"
    burn_label(path, label)
    img = np.asarray(Image.open(path).convert("RGB")).astype(int)
    changed = np.any(img != sky, axis=2)
    rows, cols = np.nonzero(changed)
    box = img[: rows.max() + 1, : cols.max() + 1]
    lum = box.mean(axis=2)
    assert np.median(lum) < 60  # a dark box behind the text ...
    assert (lum > 200).mean() > 0.02  # ... and light text on it
    assert cols.max() < img.shape[1] - 1  # wrapped: no line runs off the right edge
    assert rows.max() > 2 * 12  # a label this long takes more than one line of 12 px
    assert rows.max() < img.shape[0] // 2  # and leaves the picture to the picture


def test_on_a_thumbnail_the_label_keeps_to_the_top_third(tmp_path):
    path = tmp_path / "0001.png"
    Image.new("RGB", (96, 64), (222, 208, 180)).save(path)
    burn_label(path, "tiny " + "  ".join(f"--set render.option{i}=value{i}" for i in range(8)))
    img = np.asarray(Image.open(path).convert("RGB")).astype(int)
    rows = np.nonzero(np.any(img != (222, 208, 180), axis=2))[0]
    assert rows.max() <= 64 // 3  # the picture stays visible below it
