"""The material looks as data: what tells the materials apart, and glints sized in pixels."""

import math

import pytest

from mpmfx.render.looks import DEFAULT_LOOK, LOOKS, metres_per_pixel, sparkle


def luminance(rgb) -> float:
    """Rec. 709 luminance of a linear RGB colour."""
    r, g, b = rgb
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


def saturation(rgb) -> float:
    return 1.0 - min(rgb) / max(rgb)


def test_damp_sand_is_darker_more_saturated_and_glossier_than_dry_sand():
    dry, damp = (LOOKS[DEFAULT_LOOK[p]] for p in ("Granular", "CohesiveGranular"))
    for key in ("Base Color", "grain"):
        d, w = (s["bsdf"]["Base Color"] if key == "Base Color" else s["grain"] for s in (dry, damp))
        # water in the pores: half or less of dry sand's brightness, so the two read apart in a render
        assert luminance(w) <= 0.45 * luminance(d), key
        assert saturation(w) >= saturation(d) + 0.1, key
    assert damp["bsdf"]["Roughness"] < dry["bsdf"]["Roughness"]
    assert damp["bsdf"]["Specular IOR Level"] > dry["bsdf"]["Specular IOR Level"]


# the preset stills' camera (lab/preset_stills.py): 1.41 m from the pillar, 35 mm lens, 36 mm film
CAMERA = {
    "position": (0.66, 0.7, 1.06),
    "look_at": (-0.06, 0.1, 0.0),
    "focal_length": 35.0,
    "horizontal_aperture": 36.0,
}


def glint_pixels(width: int, camera=CAMERA) -> float:
    """The diameter (pixels) of a snow glint's core in a render `width` pixels wide."""
    pixel_m = metres_per_pixel(camera, width)
    cell, core, _ = sparkle("snow", pixel_m)
    return 2.0 * core * cell / pixel_m


def test_metres_per_pixel_is_the_view_width_at_the_subject_over_the_pixels():
    camera = {
        "position": (0.0, 0.0, 3.5),
        "look_at": (0.0, 0.0, 0.0),
        "focal_length": 35.0,
        "horizontal_aperture": 36.0,
    }
    assert metres_per_pixel(camera, 1800) == pytest.approx(3.5 * 36.0 / 35.0 / 1800)


@pytest.mark.parametrize("width", [320, 480, 960, 1920, 3840])
def test_a_snow_glint_is_the_same_few_pixels_at_any_resolution(width):
    assert 1.0 <= glint_pixels(width) <= 2.5
    assert glint_pixels(width) == pytest.approx(glint_pixels(480))


def test_snow_glints_shrink_in_metres_as_the_render_grows_or_the_camera_closes_in():
    cell = {w: sparkle("snow", metres_per_pixel(CAMERA, w))[0] for w in (480, 1920)}
    assert cell[1920] == pytest.approx(cell[480] / 4)
    near = {**CAMERA, "position": tuple((p + q) / 2 for p, q in zip(CAMERA["position"], CAMERA["look_at"]))}
    assert sparkle("snow", metres_per_pixel(near, 480))[0] == pytest.approx(cell[480] / 2)
    # the glints still cover the same share of the surface
    _, core, _ = sparkle("snow", metres_per_pixel(CAMERA, 1920))
    assert 4.0 / 3.0 * math.pi * core**3 == pytest.approx(LOOKS["snow"]["sparkle"][1])


def test_looks_without_glints_have_none():
    assert sparkle("sand", 0.002) is None
