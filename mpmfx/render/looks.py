"""Material looks for Cycles renders: what each material preset looks like, as plain data.

A look is a set of Principled BSDF inputs (Blender 4.x names) plus a few extras that
`mpmfx.render.blender_scene` turns into node graphs: a procedural bump (grain) and a volume
absorption inside transmissive surfaces. Lengths are metres (the USD stage is metres, and so
is Blender's scene after import).

This module is plain Python, read by both sides: the render stage picks a look per surface
group (`look_for`), and the Blender child process builds the materials (`LOOKS`).
"""

from __future__ import annotations

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
#          "clear_shadow": True where shadow rays pass straight through (optional; glass)}
LOOKS: dict[str, dict] = {
    # Clear, refractive, slightly blue-green in depth: the absorption tints thick water only.
    "water": {
        "bsdf": {"Base Color": (1.0, 1.0, 1.0), "Roughness": 0.03, "IOR": 1.333, "Transmission Weight": 1.0},
        "absorb": ((0.55, 0.82, 0.88), 6.0),
        "bump": None,
        "grain": None,
    },
    # White, bright, light scattering under the surface over about a centimetre.
    "snow": {
        "bsdf": {
            "Base Color": (0.93, 0.95, 0.98),
            "Roughness": 0.55,
            "Subsurface Weight": 1.0,
            "Subsurface Radius": (1.0, 1.0, 1.25),
            "Subsurface Scale": 0.01,
            "Specular IOR Level": 0.35,
        },
        "bump": (0.004, 0.25, 0.002),
        "absorb": None,
        "grain": None,
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
    # Rough and granular: grain-sized noise in colour and bump (no gloss).
    "sand": {
        "bsdf": {"Base Color": (0.60, 0.42, 0.21), "Roughness": 0.95, "Specular IOR Level": 0.2},
        "bump": (0.0015, 0.6, 0.0015),
        "absorb": None,
        "grain": (0.40, 0.27, 0.13),
    },
    "wet_sand": {
        "bsdf": {"Base Color": (0.40, 0.28, 0.15), "Roughness": 0.55, "Specular IOR Level": 0.45},
        "bump": (0.002, 0.5, 0.0015),
        "absorb": None,
        "grain": (0.28, 0.19, 0.10),
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
            "Base Color": (0.95, 0.16, 0.24),
            "Roughness": 0.12,
            "Subsurface Weight": 1.0,
            "Subsurface Radius": (1.0, 0.25, 0.3),
            "Subsurface Scale": 0.06,
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
    # A dark, slightly warm stone floor: snow, water and jelly all read against it.
    "ground": {
        "bsdf": {"Base Color": (0.11, 0.105, 0.10), "Roughness": 0.6},
        "bump": (0.03, 0.08, 0.002),
        "absorb": None,
        "grain": (0.075, 0.07, 0.065),
    },
}


# Scene props that `render.looks` may also name: the basin drawn along the solver's side walls
# (stone by default).
PROP_LOOKS = {"basin": "ground"}


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
