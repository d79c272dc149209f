"""Builds the meshes in assets/ (made for this project with trimesh + manifold3d; CC0).

Run: .venv/bin/python assets/make_assets.py   (deterministic; sizes in metres)
"""

from pathlib import Path

import numpy as np
import trimesh
from trimesh.creation import box, capsule, cylinder, icosphere

HERE = Path(__file__).parent


def union(*meshes):
    return trimesh.boolean.union(list(meshes), engine="manifold")


def at(mesh, x, y, z):
    mesh = mesh.copy()
    mesh.apply_translation([x, y, z])
    return mesh


def jelly_bear():
    """A gummy bear, ~0.4 m tall, standing on y = 0; every limb >= 0.1 m across (5 cells at dx 2 cm)."""
    body = icosphere(3, 0.09)
    body.apply_scale([1.0, 1.2, 0.85])
    parts = [
        at(body, 0, 0.14, 0),
        at(icosphere(3, 0.08), 0, 0.28, 0),
        at(icosphere(3, 0.07), -0.07, 0.35, 0),
        at(icosphere(3, 0.07), 0.07, 0.35, 0),
        at(icosphere(3, 0.045), 0, 0.26, 0.06),
    ]
    for s in (-1, 1):
        arm = capsule(height=0.06, radius=0.05)
        arm.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2.6 * s, [0, 0, 1]))
        parts.append(at(arm, 0.09 * s, 0.17, 0))
        parts.append(at(capsule(height=0.04, radius=0.055), 0.05 * s, 0.05, 0))
    m = union(*parts)
    m.apply_translation([0, -m.bounds[0][1], 0])
    return m


def snowball():
    return icosphere(4, 0.15)


def sand_column():
    c = cylinder(radius=0.12, height=0.4, sections=48)  # trimesh's axis is z; stand it up along y
    c.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))
    c.apply_translation([0, 0.2, 0])
    return c


def slab(x, y, z):
    b = box(extents=[x, y, z])
    b.apply_translation([0, y / 2, 0])
    return b


def thin_fin():
    """A ball with a 1 cm fin: fails the five-cell check at any usual grid (for `mpmfx check`)."""
    fin = box(extents=[0.3, 0.2, 0.01])
    return union(icosphere(4, 0.1), at(fin, 0.15, 0, 0))


def sand_castle():
    """A sand castle for the GPU hero shot, standing on y = 0: a 0.6 m square base 0.16 m tall, four
    corner towers and a central keep (0.5 m tall), each >= 0.14 m across (18 cells at dx 7.8 mm)."""

    def tower(r, h, x, z):
        t = cylinder(radius=r, height=h, sections=32)
        t.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))
        return at(t, x, h / 2, z)

    parts = [slab(0.6, 0.16, 0.6), slab(0.36, 0.3, 0.36), tower(0.13, 0.5, 0, 0)]
    parts += [tower(0.075, 0.34, x, z) for x in (-0.27, 0.27) for z in (-0.27, 0.27)]
    return union(*parts)


def glass():
    """A tumbler for water_pour, standing on y = 0: 0.32 m across, 0.26 m tall, walls and bottom
    5 cm thick: three cells at its shot's dx (1.7 cm), so that a grid collider holds water (two
    let it seep through)."""

    def upright(r, h, y0):
        c = cylinder(radius=r, height=h, sections=48)
        c.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))
        return at(c, 0, y0 + h / 2, 0)

    return trimesh.boolean.difference([upright(0.17, 0.26, 0.0), upright(0.11, 0.3, 0.06)], engine="manifold")


def main():
    meshes = {
        "jelly_bear.obj": jelly_bear(),
        "snowball.obj": snowball(),
        "sand_column.obj": sand_column(),
        "water_pool.obj": slab(0.7, 0.06, 0.7),
        "water_dam.obj": slab(0.3, 0.4, 0.5),
        "snow_block.obj": slab(0.3, 0.15, 0.3),
        "snow_bed.obj": slab(0.45, 0.12, 0.4),
        "thin_fin.obj": thin_fin(),
        "sand_castle.obj": sand_castle(),
        "glass.obj": glass(),
    }
    for name, m in meshes.items():
        assert m.is_watertight, name
        m.export(HERE / name)
        print(f"{name}: {len(m.faces)} faces, {m.volume * 1e3:.2f} L")


if __name__ == "__main__":
    main()
