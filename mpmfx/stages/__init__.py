"""mpmfx.stages."""
