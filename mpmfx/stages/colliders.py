"""A shot's colliders as the plain values of `mpmfx.geometry.colliders` (the geometry layer does
not read the shot schema); shared by the simulate, export and render stages."""

from __future__ import annotations

import functools

import numpy as np

from mpmfx.config import ColliderCfg, Shot, ShotError
from mpmfx.geometry.animated import load_animation
from mpmfx.geometry.colliders import ColliderGeometry, collider_mesh, keyframes
from mpmfx.geometry.common import MeshError
from mpmfx.mpm.colliders import pose_matrix


def collider_geometry(col: ColliderCfg) -> ColliderGeometry:
    """A shot's collider as a `ColliderGeometry`."""
    return ColliderGeometry(
        shape=col.shape.value,
        normal=tuple(col.normal),
        half_extents=tuple(col.half_extents),
        radius=col.radius,
        mesh=col.mesh,
        scale=col.scale,
        times=tuple(k.time for k in col.keyframes),
        translations=tuple(tuple(k.translate) for k in col.keyframes),
        rotations=tuple(tuple(k.rotate) for k in col.keyframes),
    )


def collider_key(col: ColliderCfg) -> dict:
    """The collider's settings for a cache key; `animated` only where set, so the keys of
    shots without animated colliders stay what they were."""
    d = col.model_dump(mode="json")
    if not col.animated:
        d.pop("animated")
    return d


def static_collider_mesh(shot: Shot, index: int):
    """Collider `index`'s surface in its local frame (m), a trimesh (`collider_mesh`); an asset
    that cannot be loaded is a ShotError naming the file and the key (exit 2)."""
    col = shot.colliders[index]
    try:
        return collider_mesh(collider_geometry(col), resolve=shot.resolve, plane_size=2 * shot.domain.size)
    except MeshError as exc:
        raise ShotError(f"{shot.source or shot.base_dir}: colliders[{index}].mesh ({col.name}): {exc}") from None


def check_collider_meshes(shot: Shot) -> None:
    """Load every mesh collider that is not animated (the animated ones are read when sampled),
    so a bad asset is refused before any stage runs."""
    for i, col in enumerate(shot.colliders):
        if col.shape.value == "mesh" and not col.animated:
            static_collider_mesh(shot, i)


def animated_collider(shot: Shot, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Collider `index` (animated = true) at every shot frame: (times (F,) s on the shot clock,
    points (F, V, 3) float64 world metres (the file's animation, scaled, then the keyframed
    pose at that time), faces (T, 3) int64). ShotError naming the file and the key where the
    animation cannot be used (range, topology, format)."""
    col = shot.colliders[index]
    frames = tuple(shot.frames)
    try:
        path = shot.resolve(col.mesh)
        pts, faces = _sampled(path, path.stat().st_mtime_ns, frames, float(shot.shot.fps))
    except MeshError as exc:  # the asset: bad input, exit 2
        raise ShotError(f"{shot.source or shot.base_dir}: colliders[{index}].mesh ({col.name}): {exc}") from None
    times = (np.asarray(frames, float) - shot.shot.frame_start) / shot.shot.fps
    geom = collider_geometry(col)
    out = np.empty(pts.shape, float)
    for i, t in enumerate(times):
        xf = pose_matrix(*keyframes(geom), t)
        out[i] = (pts[i] * col.scale) @ xf[:3, :3].T + xf[:3, 3]
    return times, out, faces


@functools.lru_cache(maxsize=8)
def _sampled(path, mtime: int, frames: tuple, fps: float):
    """load_animation, once a process for (file, its mtime, frames, fps): export and render
    ask for it at every frame."""
    anim = load_animation(path, frames, fps)
    anim.points.setflags(write=False)
    return anim.points, anim.faces
