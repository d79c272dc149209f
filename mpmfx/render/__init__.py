"""mpmfx.render."""
