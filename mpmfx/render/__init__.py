"""Offscreen renders: shot frames, particle debug views, thickness heatmaps (PyVista)."""


def import_pyvista():
    """pyvista set up for offscreen use, quiet about the missing X display it falls back from."""
    try:
        import pyvista as pv  # optional: pyvista
    except ImportError as exc:  # a GPU farm node may run stages without pyvista
        raise ImportError("rendering needs pyvista: run `bash setup.sh` (or pip install pyvista)") from exc
    pv.OFF_SCREEN = True
    pv.vtk_verbosity("off")
    return pv
