"""mpmfx.mpm."""
