"""The thickness check of one asset: its mesh, domain, topology and report (`mpmfx check ASSET`
prints it and draws the heatmap: mpmfx.check)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from mpmfx.geometry.mesh import MeshError, load_mesh
from mpmfx.geometry.thickness import ThicknessReport, check_thickness, refine_for_heatmap

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
    return {"watertight": open_ == 0 and non_manifold == 0, "open_edges": open_, "non_manifold_edges": non_manifold}


def topology_line(t: dict) -> str:
    if t["watertight"]:
        return "closed (watertight, manifold)"
    return (
        f"OPEN: {t['open_edges']} open edges, {t['non_manifold_edges']} non-manifold edges; inside is "
        f"guessed near them: close the holes in your DCC"
    )


@dataclass
class AssetCheck:
    """An asset's check: the mesh refined for the heatmap (m), the domain, its topology
    (mesh_topology) and the thickness report."""

    mesh: trimesh.Trimesh
    origin: np.ndarray
    size: float
    topology: dict
    report: ThicknessReport

    def to_dict(self) -> dict:
        """The report as JSON data, with the domain and the mesh's topology."""
        data = self.report.to_dict()
        data["domain"] = {"origin": [float(x) for x in self.origin], "size": float(self.size)}
        data["mesh"] = self.topology
        return data


def check_asset(asset: str, *, grid_n: int, origin=None, size=None, prim_path: str | None = None) -> AssetCheck:
    """Check ``asset``'s thickness at ``grid_n`` cells per domain edge (only its part
    ``prim_path``, as mpmfx.geometry.mesh.load_mesh takes it, where given).

    origin (3,) m and size (m) give the domain (default: the mesh bbox cube, padded 10 %).
    Raises MeshError (a ValueError) on bad input.
    """
    if grid_n < 1:
        raise MeshError(f"--grid-n {grid_n}: must be a positive number of cells")
    mesh = load_mesh(asset, prim_path=prim_path)
    if (origin is None) != (size is None):
        raise MeshError("--domain needs all of ox,oy,oz,size (or leave it out to use the asset's padded bounding cube)")
    if origin is None:
        origin, size = default_domain(mesh)
    elif size <= 0:
        raise MeshError(f"--domain size {size}: must be positive")
    return check_placed(mesh, grid_n=grid_n, origin=origin, size=size, name=Path(asset).name)


def check_placed(mesh, *, grid_n: int, origin, size: float, name: str) -> AssetCheck:
    """The check of a mesh already in place (m): a shot's object, or a whole asset."""
    topology = mesh_topology(mesh)
    mesh = refine_for_heatmap(mesh, grid_n=grid_n, size=size)
    report = check_thickness(mesh, grid_n=grid_n, origin=origin, size=size, name=name)
    return AssetCheck(mesh, np.asarray(origin, float), size, topology, report)
