"""mpmfx."""
