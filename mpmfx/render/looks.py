"""Material looks for Cycles renders: what each material preset looks like, as plain data.

A look is a set of Principled BSDF inputs (Blender 4.x names) plus a few extras that
`mpmfx.render.blender_scene` turns into node graphs: a procedural bump (grain) and a volume
absorption inside transmissive surfaces. Lengths are metres (the USD stage is metres, and so
is Blender's scene after import).

This module is plain Python, read by both sides: the render stage picks a look per surface
group (`look_for`), and the Blender child process builds the materials (`LOOKS`).
"""

from __future__ import annotations

import math

# The look of each preset (docs/physics.md, "Materials"), by what the material is, not by
# its name's promise (the names describe intent, not physics): the snow ladder reads as snow from
# packed (Soft) to slush (Wet, Slush); CohesiveGranular as damp sand; Elastic as jelly.
DEFAULT_LOOK = {
    "Soft": "snow",
    "Mushy": "snow",
    "Goopy": "snow",
    "Wet": "slush",
    "Slush": "slush",
    "Elastic": "jelly",
    "Granular": "sand",
    "CohesiveGranular": "wet_sand",
    "Water": "water",
    "Tracer": "plastic",
}

# name -> {"bsdf": Principled inputs, "bump": (feature size m, strength, distance m) or None,
#          "absorb": (colour, density 1/m) for a volume absorption inside, or None,
#          "grain": second base colour mixed in by a fine noise (sand grains), or None,
#          optional:
#          "cells": True where the grain is one colour per grain-sized cell (Voronoi), with each
#                   grain a small dome in the bump, instead of a smooth noise,
#          "sparkle": (glint size px, fraction of the surface, weight): sparse mirror-like glints,
#                   each cell's facet tilted at random (snow crystals); the size is in pixels of
#                   the render (`sparkle`), so a glint is a point of light at any resolution,
#          "clear_shadow": True where shadow rays pass straight through (glass, water: with
#                   caustics off, a refracting surface would otherwise cast a solid shadow)}
LOOKS: dict[str, dict] = {
    # Clear, refractive, slightly blue-green in depth: the absorption (about 0.4 1/m in red, as in
    # clean water seen through tens of centimetres) tints thick water only. Light reaches the floor
    # under it (clear shadows), so the water shows a lit floor and the sky, not a dark pit.
    "water": {
        "bsdf": {"Base Color": (1.0, 1.0, 1.0), "Roughness": 0.02, "IOR": 1.333, "Transmission Weight": 1.0},
        "absorb": ((0.74, 0.92, 0.95), 2.0),
        "bump": None,
        "grain": None,
        "clear_shadow": True,
    },
    # White, bright, light scattering under the surface over millimetres (bluer deeper in),
    # a crumbly bump, and sparse glints: 2 % of the surface is crystal facets two pixels of the
    # render across at any width (the denoiser erases finer ones; lab/glint_scale.py measures
    # 2.1 px at 480 and at 1920 px wide), tilted at random, that mirror the sun and sky as
    # points of light (at four times a mirror's weight: under the view transform's highlight
    # roll-off, weaker glints vanish into the white snow).
    "snow": {
        "bsdf": {
            "Base Color": (0.86, 0.89, 0.94),
            "Roughness": 0.6,
            "Subsurface Weight": 1.0,
            "Subsurface Radius": (0.8, 0.95, 1.3),
            "Subsurface Scale": 0.006,
            "Specular IOR Level": 0.3,
        },
        "bump": (0.02, 0.7, 0.006),
        "absorb": None,
        "grain": None,
        "sparkle": (2.0, 0.02, 4.0),
    },
    "slush": {
        "bsdf": {
            "Base Color": (0.86, 0.91, 0.96),
            "Roughness": 0.18,
            "Subsurface Weight": 1.0,
            "Subsurface Radius": (0.9, 1.0, 1.3),
            "Subsurface Scale": 0.02,
            "Transmission Weight": 0.15,
            "IOR": 1.31,
        },
        "bump": (0.006, 0.15, 0.002),
        "absorb": None,
        "grain": None,
    },
    # Rough and granular: one colour per grain (3 mm cells: visible at 480 px across a metre) over
    # a slower mottle, and each grain a small dome in the bump (no gloss).
    "sand": {
        "bsdf": {"Base Color": (0.66, 0.49, 0.28), "Roughness": 0.95, "Specular IOR Level": 0.2},
        "bump": (0.003, 0.5, 0.0015),
        "absorb": None,
        "grain": (0.42, 0.30, 0.16),
        "cells": True,
    },
    # Damp sand: water in the pores darkens it to about a third of dry sand's brightness and
    # deepens its colour (less light scattered back white from the grains' faces), and the film
    # between the grains gives a soft sheen; the grains' domes flatter under it.
    "wet_sand": {
        "bsdf": {"Base Color": (0.30, 0.17, 0.07), "Roughness": 0.45, "Specular IOR Level": 0.5},
        "bump": (0.003, 0.3, 0.0015),
        "absorb": None,
        "grain": (0.19, 0.10, 0.04),
        "cells": True,
    },
    "mud": {
        "bsdf": {"Base Color": (0.22, 0.15, 0.09), "Roughness": 0.3, "Coat Weight": 0.4, "Coat Roughness": 0.15},
        "bump": (0.01, 0.3, 0.003),
        "absorb": None,
        "grain": (0.16, 0.11, 0.07),
    },
    # Translucent and coloured: gummy-bear red, light travelling centimetres inside, glossy skin.
    "jelly": {
        "bsdf": {
            "Base Color": (0.85, 0.06, 0.10),
            "Roughness": 0.12,
            "Subsurface Weight": 1.0,
            "Subsurface Radius": (1.0, 0.15, 0.18),
            "Subsurface Scale": 0.05,
            "Coat Weight": 1.0,
            "Coat Roughness": 0.04,
            "IOR": 1.45,
        },
        "bump": None,
        "absorb": None,
        "grain": None,
    },
    "plastic": {
        "bsdf": {"Base Color": (1.0, 0.82, 0.25), "Roughness": 0.35},
        "bump": None,
        "absorb": None,
        "grain": None,
    },
    # Scene props: colliders and the ground.
    "collider": {
        "bsdf": {"Base Color": (0.32, 0.34, 0.37), "Roughness": 0.35, "Metallic": 0.6},
        "bump": None,
        "absorb": None,
        "grain": None,
    },
    # Clear glass for a tank's walls (`render.looks = {basin = "glass"}`): shadow rays pass
    # through it (with caustics off, refracting walls would otherwise shade the water in them).
    "glass": {
        "bsdf": {"Base Color": (1.0, 1.0, 1.0), "Roughness": 0.0, "IOR": 1.5, "Transmission Weight": 1.0},
        "bump": None,
        "absorb": None,
        "grain": None,
        "clear_shadow": True,
    },
    # A mid-grey, slightly warm stone floor: white snow and red jelly read against it, and clear
    # water shows it lit through the surface.
    "ground": {
        "bsdf": {"Base Color": (0.16, 0.15, 0.14), "Roughness": 0.6},
        "bump": (0.03, 0.08, 0.002),
        "absorb": None,
        "grain": (0.11, 0.105, 0.10),
    },
}

# The world: one of the studio HDRIs that Blender ships (datafiles/studiolights/world, CC0, by
# Greg Zaal, from Poly Haven: "city" is Portland Landing Pad, a clear sky over a skyline). It
# lights the scene and is what water and glass reflect and refract; its own sun is clamped to
# WORLD["clamp"] (a lamp along render.sun_elevation / sun_rotation casts the sharp shadows, and
# the HDRI is turned so that its sun, at azimuth `sun_azimuth` degrees (from +x towards +y,
# Blender axes), stands where the lamp is). Strength multiplies the HDRI. Camera rays see it
# lifted by `horizon_lift` (the tangent of the elevation that their horizon shows: 61 degrees,
# over the tallest tower), so the background is sky, not the HDRI's own skyline; reflections
# see the skyline.
WORLD = {"hdri": "city", "sun_azimuth": -36.0, "clamp": 6.0, "strength": 0.8, "sun_strength": 3.0, "horizon_lift": 1.8}

# The ground: a plane `GROUND_SPAN` domain sizes across (at least GROUND_MIN m), so that it runs
# to the horizon from any camera over the shot; beyond `GROUND_FADE` (near, far) domain sizes
# from the camera it fades into the world's colour at the horizon, so it meets the sky with no
# edge and far texture does not alias.
GROUND_SPAN, GROUND_MIN, GROUND_FADE = 4000.0, 1000.0, (8.0, 120.0)


# Scene props that `render.looks` may also name: the basin drawn along the solver's side walls
# (stone by default).
PROP_LOOKS = {"basin": "ground"}


# A metre across 480 pixels: the scale a look's pixel sizes mean where no camera is known.
DEFAULT_PIXEL_M = 1.0 / 480.0


def metres_per_pixel(camera: dict, width: int) -> float:
    """The width (m) one pixel of a `width`-pixel-wide render covers at the camera's look-at
    point: its distance times the film's width over the focal length (both mm; horizontal fit),
    over `width`. camera: `mpmfx.render.camera.render_camera`'s dict."""
    distance = math.dist(camera["position"], camera["look_at"])
    return distance * float(camera["horizontal_aperture"]) / float(camera["focal_length"]) / int(width)


def sparkle(look: str, pixel_m: float = DEFAULT_PIXEL_M) -> tuple[float, float, float] | None:
    """The glints of `look` for a render whose pixel covers `pixel_m` metres at the subject:
    (Voronoi cell size m, core radius in cell sizes, weight), or None for a look without glints.
    A glint is the core of a cell (`LOOKS[look]["sparkle"]` = (size px, fraction, weight)): a
    ball of radius r in a unit cell covers (4/3) pi r^3 of it, and its diameter 2 r cells spans
    `size px` pixels, so the cells shrink as the render's pixels do."""
    spec = LOOKS[look].get("sparkle")
    if not spec:
        return None
    size_px, fraction, weight = spec
    core = (3.0 * fraction / (4.0 * math.pi)) ** (1.0 / 3.0)
    return size_px * pixel_m / (2.0 * core), core, weight


def look_for(names: list[str], overrides: dict[str, str] | None = None) -> str:
    """The look of a surface group or object: the first of `names` (its group or object name,
    then its preset) that `overrides` (`render.looks`) names, else the preset's default."""
    overrides = overrides or {}
    for name in names:
        if name in overrides:
            return overrides[name]
    return DEFAULT_LOOK.get(names[-1], "plastic")


def preview_surface(look: str) -> dict:
    """`look` as UsdPreviewSurface inputs, for DCCs that import the USD: colour (linear RGB; a
    clear look shows the tint of its depth), roughness, metallic, opacity (1 opaque; a clear
    look is mostly see-through) and ior."""
    spec = LOOKS[look]
    bsdf = spec["bsdf"]
    clear = float(bsdf.get("Transmission Weight", 0.0))
    colour = spec["absorb"][0] if spec.get("absorb") and clear > 0.5 else bsdf["Base Color"]
    return {
        "colour": tuple(float(c) for c in colour),
        "roughness": float(bsdf.get("Roughness", 0.5)),
        "metallic": float(bsdf.get("Metallic", 0.0)),
        "opacity": round(1.0 - 0.75 * clear, 4),
        "ior": float(bsdf.get("IOR", 1.5)),
    }
