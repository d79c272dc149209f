"""``mpmfx check ASSET``: thickness report for one asset, as a table or JSON."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from mpmfx.geometry.mesh import MeshError, load_mesh
from mpmfx.geometry.thickness import Verdict, check_thickness, refine_for_heatmap

# The default domain is the mesh's bounding cube grown by this fraction.
DEFAULT_PADDING = 0.10


def default_domain(mesh) -> tuple[np.ndarray, float]:
    """(origin (3,) m, size m): the mesh bbox's bounding cube, padded 10 %, same centre."""
    size = float(mesh.extents.max()) * (1.0 + DEFAULT_PADDING)
    centre = np.asarray(mesh.bounds, float).mean(axis=0)
    return centre - size / 2.0, size


def mesh_topology(mesh) -> dict:
    """Edges used by one face (open: a hole) and by more than two (non-manifold). Either makes
    inside/outside ambiguous there, which voxelise warns about and the thickness check inherits."""
    _, counts = np.unique(np.asarray(mesh.edges_sorted), axis=0, return_counts=True)
    open_, non_manifold = int((counts == 1).sum()), int((counts > 2).sum())
    return {"watertight": open_ == 0 and non_manifold == 0, "open_edges": open_,
            "non_manifold_edges": non_manifold}


def _topology_line(t: dict) -> str:
    if t["watertight"]:
        return "closed (watertight, manifold)"
    return (f"OPEN: {t['open_edges']} open edges, {t['non_manifold_edges']} non-manifold edges; inside is "
            f"guessed near them: close the holes in your DCC")


def run_check(asset: str, *, grid_n: int, origin=None, size=None, as_json: bool = False,
              out_dir: str | Path | None = None, prim_path: str | None = None) -> int:
    """Check ``asset``'s thickness at ``grid_n`` cells per domain edge (only its part
    ``prim_path``, as mpmfx.geometry.mesh.load_mesh takes it, where given).

    origin (3,) m and size (m) give the domain (default: the mesh bbox cube, padded 10 %).
    Prints the table (or JSON with ``as_json``) to stdout, writes ``report.json`` and
    ``thickness.png`` to ``out_dir`` (default ./renders/check/<asset stem>/).
    Returns 0 on PASS or WARN, 1 on FAIL, 2 on bad input (message on stderr).
    """
    try:
        if grid_n < 1:
            raise MeshError(f"--grid-n {grid_n}: must be a positive number of cells")
        mesh = load_mesh(asset, prim_path=prim_path)
        if (origin is None) != (size is None):
            raise MeshError("--domain needs all of ox,oy,oz,size (or leave it out to use "
                            "the asset's padded bounding cube)")
        if origin is None:
            origin, size = default_domain(mesh)
        elif size <= 0:
            raise MeshError(f"--domain size {size}: must be positive")
        topology = mesh_topology(mesh)
        mesh = refine_for_heatmap(mesh, grid_n=grid_n, size=size)
        report = check_thickness(mesh, grid_n=grid_n, origin=origin, size=size,
                                 name=Path(asset).name)
    except ValueError as exc:  # MeshError included
        print(f"mpmfx check: {exc}", file=sys.stderr)
        return 2
    out = Path(out_dir) if out_dir is not None else Path("renders/check") / Path(asset).stem
    out.mkdir(parents=True, exist_ok=True)
    data = report.to_dict()
    data["domain"] = {"origin": [float(x) for x in origin], "size": float(size)}
    data["mesh"] = topology
    (out / "report.json").write_text(json.dumps(data, indent=2) + "\n")
    from mpmfx.render.thickness import render_thickness_heatmap

    png = render_thickness_heatmap(mesh, report.vertex_thickness_cells, out / "thickness.png",
                                   warn_cells=report.warn_cells)
    if as_json:
        print(json.dumps(data, indent=2))
    else:
        print(report.format_table())
        print(f"  mesh               {_topology_line(topology)}")
        if any(r.thickness_cells == 0 for r in report.regions):
            print("  (0.00 cells: parts thinner than the measuring lattice, which no grid_n here resolves)")
        print(f"  wrote {out / 'report.json'} and {png}")
    return 1 if report.verdict is Verdict.FAIL else 0
