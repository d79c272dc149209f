"""mpmfx.surface: particles -> narrow-band level set -> triangle mesh (numpy + Warp only).

Returns arrays; the pipeline's stages write them to USD / VDB.
"""

from mpmfx.surface.params import (
    PARTICLE_RADIUS_PER_SPACING,
    GridTooLarge,
    LevelSet,
    SparseLevelSet,
    SurfaceMesh,
    SurfaceParams,
    SurfaceResult,
)
from mpmfx.surface.reconstruct import surface_particles

__all__ = [
    "PARTICLE_RADIUS_PER_SPACING",
    "GridTooLarge",
    "LevelSet",
    "SparseLevelSet",
    "SurfaceMesh",
    "SurfaceParams",
    "SurfaceResult",
    "surface_particles",
]
