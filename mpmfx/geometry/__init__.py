"""mpmfx.geometry."""

MESH_LOADING = (
    "mpmfx.geometry.mesh",
    "mpmfx.geometry.common",
    "mpmfx.geometry.usd_asset",
    "mpmfx.geometry.subdivide",
    "mpmfx.geometry.blender_export",
)
"""The modules that decide what an asset file loads as (a stage's CODE names them all)."""
