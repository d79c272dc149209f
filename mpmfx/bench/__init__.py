"""mpmfx.bench."""
