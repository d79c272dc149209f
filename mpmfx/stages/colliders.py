"""Colliders: the shot's [[colliders]] as solver arrays (domain units) and as USD samples (world).

A stage builds them; the solver never reads a config or a mesh file (DESIGN.md, seams).
"""
from __future__ import annotations

import numpy as np

from mpmfx.cache import file_hash
from mpmfx.config import ColliderCfg, ColliderShape, Shot


def inputs(shot: Shot) -> dict[str, str]:
    return {f"collider:{c.name}": file_hash(shot.resolve(c.mesh)) for c in shot.colliders
            if c.shape is ColliderShape.MESH and c.mesh is not None}


def _quat_xyzw(rotate_deg) -> np.ndarray:
    """XYZ Euler degrees (applied x, then y, then z) -> quaternion (x, y, z, w)."""
    hx, hy, hz = np.radians(np.asarray(rotate_deg, float)) / 2
    qx = np.array([np.sin(hx), 0, 0, np.cos(hx)])
    qy = np.array([0, np.sin(hy), 0, np.cos(hy)])
    qz = np.array([0, 0, np.sin(hz), np.cos(hz)])
    return _qmul(qz, _qmul(qy, qx))


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def keyframes(col: ColliderCfg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """times (k,) s, translations (k,3) m, rotations (k,4) xyzw."""
    t = np.array([k.time for k in col.keyframes], float)
    tr = np.array([k.translate for k in col.keyframes], float)
    rot = np.array([_quat_xyzw(k.rotate) for k in col.keyframes], float)
    return t, tr, rot


def collider_mesh(shot: Shot, col: ColliderCfg):
    """The collider's surface in its local frame (m), as a trimesh (used for USD and mesh SDFs)."""
    import trimesh
    if col.shape is ColliderShape.MESH:
        from mpmfx.geometry.mesh import load_mesh, transform_mesh
        return transform_mesh(load_mesh(shot.resolve(col.mesh)), scale=col.scale)
    if col.shape is ColliderShape.BOX:
        return trimesh.creation.box(extents=2 * np.asarray(col.half_extents))
    if col.shape is ColliderShape.SPHERE:
        return trimesh.creation.icosphere(subdivisions=3, radius=col.radius)
    # plane: a large quad through the local origin, facing `normal`
    L = shot.domain.size * 2
    quad = trimesh.Trimesh([[-L, 0, -L], [L, 0, -L], [L, 0, L], [-L, 0, L]], [[0, 2, 1], [0, 3, 2]])
    n = np.asarray(col.normal, float) / np.linalg.norm(col.normal)
    quad.apply_transform(trimesh.geometry.align_vectors([0, 1, 0], n))
    return quad


def build(shot: Shot) -> list:
    """mpm.Collider list in domain units (positions / domain.size, about domain.origin)."""
    from mpmfx.mpm import Collider, ColliderKind
    origin, L = np.asarray(shot.domain.origin, float), shot.domain.size
    out = []
    for col in shot.colliders:
        t, tr, rot = keyframes(col)
        common = dict(friction=col.friction, times=t,  # shot clock, as the solver expects
                      translations=((tr - origin) / L).astype(np.float32), rotations=rot.astype(np.float32))
        if col.shape is ColliderShape.PLANE:
            out.append(Collider(kind=ColliderKind.PLANE, normal=tuple(col.normal), **common))
        elif col.shape is ColliderShape.BOX:
            out.append(Collider(kind=ColliderKind.BOX, half_extents=tuple(h / L for h in col.half_extents), **common))
        elif col.shape is ColliderShape.SPHERE:
            out.append(Collider(kind=ColliderKind.SPHERE, radius=col.radius / L, **common))
        else:
            sdf, sdf_origin, voxel = _mesh_sdf(shot, col)
            out.append(Collider(kind=ColliderKind.SDF, sdf=(sdf / L).astype(np.float32),
                                sdf_origin=tuple(sdf_origin / L), sdf_voxel=voxel / L, **common))
    return out


def _mesh_sdf(shot: Shot, col: ColliderCfg):
    """Signed distance (m, negative inside) of the collider mesh on a local grid at the sim's dx."""
    from mpmfx.geometry.voxelise import voxelise
    mesh = collider_mesh(shot, col)
    lo = mesh.bounds[0]
    size = float((mesh.bounds[1] - mesh.bounds[0]).max()) * 1.2 + 1e-6
    dx = shot.domain.size / shot.domain.grid_n
    vox = voxelise(mesh, origin=tuple(lo - 0.1 * size), size=size, grid_n=max(8, int(np.ceil(size / dx))), ppc=1)
    return vox.sdf, np.asarray(vox.sdf_origin, float), float(vox.sdf_voxel)


def transform_at(col: ColliderCfg, t: float) -> np.ndarray:
    """(4,4) world transform at time t (s): the solver's own keyframe interpolation (linear
    translation, slerp rotation), so what USD and the renders show is what the material felt."""
    from mpmfx.mpm import Collider, ColliderKind
    times, tr, rot = keyframes(col)
    p, (x, y, z, w) = Collider(kind=ColliderKind.PLANE, times=times, translations=tr, rotations=rot).pose(t)
    m = np.eye(4)
    m[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    m[:3, 3] = p
    return m


def usd_samples(shot: Shot, frame: int) -> list:
    from mpmfx.io.usd import ColliderSample
    t = (frame - shot.shot.frame_start) / shot.shot.fps
    out = []
    for col in shot.colliders:
        m = collider_mesh(shot, col)
        out.append(ColliderSample(name=col.name, points=np.asarray(m.vertices, np.float32),
                                  faces=np.asarray(m.faces, np.int32), xform=transform_at(col, t)))
    return out
