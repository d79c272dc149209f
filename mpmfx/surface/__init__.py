"""mpmfx.surface: particles -> narrow-band level set -> triangle mesh (numpy + Warp only).

Returns arrays; the pipeline's stages write them to USD / VDB.
"""

from mpmfx.surface.params import Grid, LevelSet, Method, SparseLevelSet, SurfaceMesh, SurfaceParams, SurfaceResult
from mpmfx.surface.reconstruct import surface_particles

__all__ = ["Grid", "LevelSet", "SparseLevelSet", "Method", "SurfaceMesh", "SurfaceParams", "SurfaceResult", "surface_particles"]
