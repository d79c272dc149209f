"""Analytic test shapes of known thickness (metres), built with trimesh / manifold3d."""

import numpy as np
import pytest
import trimesh


def slab(t: float) -> trimesh.Trimesh:
    """0.5 x 0.5 m plate, t thick (z)."""
    return trimesh.creation.box(extents=(0.5, 0.5, t))


def rod(d: float) -> trimesh.Trimesh:
    """Cylinder of diameter d, 0.6 m long (z)."""
    return trimesh.creation.cylinder(radius=d / 2, height=0.6, sections=48)


def l_bracket(t: float) -> trimesh.Trimesh:
    """Two t-thick plates (0.6 x 0.3 and 0.3 x 0.5 m) meeting at a right angle."""
    a = trimesh.creation.box(extents=(0.6, 0.3, t))
    a.apply_translation((0, 0, t / 2))
    b = trimesh.creation.box(extents=(t, 0.3, 0.5))
    b.apply_translation((0.3 - t / 2, 0, 0.25))
    return a.union(b)


def sphere_with_fin(t: float) -> trimesh.Trimesh:
    """Sphere of radius 0.2 m with a 0.3 x 0.2 m fin, t thick, sticking out along +x."""
    s = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    f = trimesh.creation.box(extents=(0.3, 0.2, t))
    f.apply_translation((0.3, 0, 0))
    return s.union(f)


DOMAIN = {"origin": (-0.5, -0.5, -0.5), "size": 1.0}


@pytest.fixture
def domain():
    return dict(DOMAIN)


def cube_asset(cube: float, *, kind: str) -> trimesh.Trimesh:
    """Hard-surface asset built of cubes of edge ``cube`` (m): a base slab 6 x 4 x 2 cubes,
    a 2 x 2 cube tower 4 cubes tall and a wall exactly one cube thick (x), 3 wide, 3 tall.

    kind "union": one watertight solid (manifold3d). "kitbash": the three boxes simply
    concatenated, tower and wall sunk into the base (internal faces, buried vertices), as
    artists' kit-bashed assets are. Same solid either way; its thinnest part is the wall.
    """

    def box(lo, hi):
        lo, hi = np.asarray(lo, float) * cube, np.asarray(hi, float) * cube
        b = trimesh.creation.box(extents=hi - lo)
        b.apply_translation((lo + hi) / 2)
        return b

    parts = [box((0, 0, 0), (6, 4, 2)), box((0, 0, 1.5), (2, 2, 6)), box((4, 0, 1.7), (5, 3, 5))]
    if kind == "union":
        return trimesh.boolean.union(parts, engine="manifold")
    return trimesh.util.concatenate(parts)


def cube_block(cube: float, n: int = 3) -> trimesh.Trimesh:
    """An n x n x n block of separate cubes of edge ``cube`` (m), concatenated as voxel art
    is: every inner face is doubled and buried. Solid and n cubes thick everywhere."""
    cubes = []
    for i in np.ndindex(n, n, n):
        b = trimesh.creation.box(extents=(cube,) * 3)
        b.apply_translation((np.asarray(i) + 0.5) * cube)
        cubes.append(b)
    return trimesh.util.concatenate(cubes)
