"""mpmfx.geometry."""
