"""mpmfx.surface."""
