"""Colliders of a shot as geometry (world units): their meshes, keyframes and signed distance.

The solver gets them as `mpmfx.mpm.Collider` arrays that the simulate stage builds from these;
the poses between keyframes always come from the solver's own interpolation
(`mpmfx.mpm.colliders.pose_matrix`), so USD and renders show what the material felt.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from mpmfx.config import ColliderCfg, ColliderShape


def keyframes(col: ColliderCfg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """times (k,) s on the shot clock, translations (k,3) m, rotations (k,4) quaternions xyzw
    (XYZ Euler degrees about the fixed world axes, as `mpmfx.geometry.mesh.transform_mesh`)."""
    from scipy.spatial.transform import Rotation
    t = np.array([k.time for k in col.keyframes], float)
    tr = np.array([k.translate for k in col.keyframes], float)
    rot = Rotation.from_euler("xyz", [k.rotate for k in col.keyframes], degrees=True).as_quat()
    return t, tr, rot


def collider_mesh(col: ColliderCfg, *, resolve: Callable[[Path], Path], plane_size: float):
    """The collider's surface in its local frame (m), a trimesh. `resolve` turns the shot's
    relative mesh path into a file; a plane is drawn as a square of 2 * plane_size a side."""
    import trimesh
    if col.shape is ColliderShape.MESH:
        from mpmfx.geometry.mesh import load_mesh, transform_mesh
        return transform_mesh(load_mesh(resolve(col.mesh)), scale=col.scale)
    if col.shape is ColliderShape.BOX:
        return trimesh.creation.box(extents=2 * np.asarray(col.half_extents))
    if col.shape is ColliderShape.SPHERE:
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
    from mpmfx.geometry.voxelise import voxelise
    lo = mesh.bounds[0]
    size = float((mesh.bounds[1] - mesh.bounds[0]).max()) * 1.2 + 1e-6
    vox = voxelise(mesh, origin=tuple(lo - 0.1 * size), size=size, grid_n=max(8, int(np.ceil(size / dx))), ppc=1)
    return vox.sdf, np.asarray(vox.sdf_origin, float), float(vox.sdf_voxel)
