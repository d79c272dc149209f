"""Colliders of a shot as geometry (world units): their meshes, keyframes and signed distance.

A collider comes in as a `ColliderGeometry` of plain values, which the stages make from the
shot's collider settings (`mpmfx.stages.base.collider_geometry`). The solver gets them as
`mpmfx.mpm.Collider` arrays that the simulate stage builds from these; the poses between
keyframes always come from the solver's own interpolation (`mpmfx.mpm.colliders.pose_matrix`),
so USD and renders show what the material felt.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from mpmfx.geometry.mesh import load_mesh, transform_mesh
from mpmfx.geometry.voxelise import voxelise

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class ColliderGeometry:
    """One collider's shape and keyframes in world units. shape: "plane", "box", "sphere" or
    "mesh"; normal: plane's outward normal; half_extents: box's (m); radius: sphere's (m); mesh:
    the mesh file as the shot names it, with its uniform scale; times (s on the shot clock),
    translations (m) and rotations (XYZ Euler degrees about the fixed world axes): the keys."""

    shape: str
    normal: Vec3 = (0.0, 1.0, 0.0)
    half_extents: Vec3 = (0.1, 0.1, 0.1)
    radius: float = 0.1
    mesh: Path | None = None
    scale: float = 1.0
    times: tuple[float, ...] = (0.0,)
    translations: tuple[Vec3, ...] = ((0.0, 0.0, 0.0),)
    rotations: tuple[Vec3, ...] = ((0.0, 0.0, 0.0),)


def keyframes(col: ColliderGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """times (k,) s on the shot clock, translations (k,3) m, rotations (k,4) quaternions xyzw
    (XYZ Euler degrees about the fixed world axes, as `mpmfx.geometry.mesh.transform_mesh`)."""
    t = np.array(col.times, float)
    tr = np.array(col.translations, float)
    rot = Rotation.from_euler("xyz", col.rotations, degrees=True).as_quat()
    return t, tr, rot


def collider_mesh(col: ColliderGeometry, *, resolve: Callable[[Path], Path], plane_size: float):
    """The collider's surface in its local frame (m), a trimesh. `resolve` turns the shot's
    relative mesh path into a file; a plane is drawn as a square of 2 * plane_size a side."""
    if col.shape == "mesh":
        return transform_mesh(load_mesh(resolve(col.mesh)), scale=col.scale)
    if col.shape == "box":
        return trimesh.creation.box(extents=2 * np.asarray(col.half_extents))
    if col.shape == "sphere":
        return trimesh.creation.icosphere(subdivisions=3, radius=col.radius)
    # plane: a large quad through the local origin, facing `normal`
    L = plane_size
    quad = trimesh.Trimesh([[-L, 0, -L], [L, 0, -L], [L, 0, L], [-L, 0, L]], [[0, 2, 1], [0, 3, 2]])
    n = np.asarray(col.normal, float) / np.linalg.norm(col.normal)
    quad.apply_transform(trimesh.geometry.align_vectors([0, 1, 0], n))
    return quad


def mesh_sdf(mesh, *, dx: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Signed distance (m, negative inside) of a closed mesh on a local grid of about `dx`
    voxels: (sdf (a,b,c) float, origin (3,) m, voxel m)."""
    lo = mesh.bounds[0]
    size = float((mesh.bounds[1] - mesh.bounds[0]).max()) * 1.2 + 1e-6
    vox = voxelise(mesh, origin=tuple(lo - 0.1 * size), size=size, grid_n=max(8, int(np.ceil(size / dx))), ppc=1)
    return vox.sdf, np.asarray(vox.sdf_origin, float), float(vox.sdf_voxel)
