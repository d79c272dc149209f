"""Thickness heatmap: the asset coloured by local thickness in sim cells (red = thin)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mpmfx.cache import atomic_path
from mpmfx.render import import_pyvista


def render_thickness_heatmap(
    mesh, vertex_thickness_cells: np.ndarray, path: str | Path, *, warn_cells: float = 5.0, window_size=(800, 600)
) -> Path:
    """Render ``mesh`` offscreen to a PNG coloured by thickness and return the path.

    mesh: trimesh.Trimesh in metres. vertex_thickness_cells: (v,) thickness per vertex in
    sim cells. Colour runs red (0 cells) through yellow to green (2 x warn_cells and above).
    """
    pv = import_pyvista()
    values = np.asarray(vertex_thickness_cells, float)
    if values.shape != (len(mesh.vertices),):
        raise ValueError(
            f"vertex_thickness_cells has shape {values.shape}; expected "
            f"({len(mesh.vertices)},), one value per mesh vertex"
        )
    faces = np.asarray(mesh.faces, np.int64)
    cells = np.hstack([np.full((len(faces), 1), 3, np.int64), faces]).ravel()
    poly = pv.PolyData(np.asarray(mesh.vertices, float), cells)
    poly.point_data["thickness (cells)"] = values
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    plotter.add_mesh(
        poly, scalars="thickness (cells)", cmap="RdYlGn", clim=[0.0, 2.0 * warn_cells], smooth_shading=True
    )
    plotter.add_text(f"thickness in cells (warn < {warn_cells:g})", font_size=10)
    # our world is Y-up (a DCC's view): from the front right, above ("iso" keeps Z up and laid
    # Y-up assets on their side)
    plotter.view_vector((0.7, 0.6, 1.0), viewup=(0.0, 1.0, 0.0))
    try:
        with atomic_path(path) as tmp:  # complete or absent; a full disk names this file
            plotter.screenshot(str(tmp))
    finally:
        plotter.close()
    return path
