"""A shot's colliders as the plain values of `mpmfx.geometry.colliders` (the geometry layer does
not read the shot schema); shared by the simulate, export and render stages."""

from __future__ import annotations

from mpmfx.config import ColliderCfg
from mpmfx.geometry.colliders import ColliderGeometry


def collider_geometry(col: ColliderCfg) -> ColliderGeometry:
    """A shot's collider as a `ColliderGeometry`."""
    return ColliderGeometry(
        shape=col.shape.value,
        normal=tuple(col.normal),
        half_extents=tuple(col.half_extents),
        radius=col.radius,
        mesh=col.mesh,
        scale=col.scale,
        times=tuple(k.time for k in col.keyframes),
        translations=tuple(tuple(k.translate) for k in col.keyframes),
        rotations=tuple(tuple(k.rotate) for k in col.keyframes),
    )
