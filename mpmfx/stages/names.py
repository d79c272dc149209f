"""What the hand-off USD calls each thing it holds, and the look each surface gets.

A DCC makes an object of each prim and names it after the prim, and Blender's object names are
one namespace: a surface is named after its object (or, where a surface group holds several,
after them all, else the group), its particles and level set after it with `_particles` /
`_vdb`; every name is a valid prim name and distinct from the others, the colliders' and the
stage's own (`mpmfx.io.usd`'s scopes).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from mpmfx.render.looks import look_for

STAGE_NAMES = ("World", "surfaces", "particles", "volumes", "colliders", "looks", "camera", "preview")
VDB_FIELDS = ("surface", "vel", "density")  # a volume's field prims: <volume>_<field>
MAX_LEN = 64  # characters of a surface named after several objects


@dataclass(frozen=True)
class UsdNames:
    """surfaces, volumes: surface group -> prim name; particles: object (body) name -> prim name."""

    surfaces: dict[str, str]
    volumes: dict[str, str]
    particles: dict[str, str]


def prim_name(text: str) -> str:
    """`text` as a valid USD prim name: letters, digits and underscores, not starting with a digit."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", text) or "_"
    return f"_{name}" if name[0].isdigit() else name


def usd_names(shot) -> UsdNames:
    taken = set(STAGE_NAMES) | {prim_name(c.name) for c in shot.colliders}

    def unique(text: str) -> str:
        base = name = prim_name(text)
        n = 1
        while name in taken:
            n += 1
            name = f"{base}_{n}"
        taken.add(name)
        return name

    members: dict[str, list[str]] = {}
    for group, body in zip(shot.surface_groups(), shot.bodies):
        members.setdefault(group, []).append(body.name)
    surfaces = {}
    for group, objects in members.items():
        joined = "_".join(objects)
        surfaces[group] = unique(joined if len(joined) <= MAX_LEN else group)
    volumes = {}
    for group, name in surfaces.items():
        volumes[group] = unique(f"{name}_vdb")
        taken.update(f"{volumes[group]}_{f}" for f in VDB_FIELDS)
    particles = {b.name: unique(f"{b.name}_particles") for b in shot.bodies}
    return UsdNames(surfaces, volumes, particles)


def surface_looks(shot) -> dict[str, str]:
    """Surface group -> its look (`mpmfx.render.looks`): `render.looks` by group, object or preset."""
    looks = shot.render.looks
    return {g: look_for([g, o.name, o.material], looks) for g, o in zip(shot.surface_groups(), shot.bodies)}
