"""mpmfx.io."""
