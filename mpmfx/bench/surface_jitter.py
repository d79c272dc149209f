"""Frame-to-frame jitter of a reconstructed surface, in particle spacings h: a body at rest whose
particles creep (rest_jitter) and a slowly moving one (moving_jitter), the columns jitter/h and
moving/h of `mpmfx bench surface` (mpmfx.bench.surface_cases)."""

from __future__ import annotations

import numpy as np
import warp as wp
from scipy.spatial import cKDTree

from mpmfx.surface import SurfaceParams, surface_particles

REST_NOISE = 0.01
"""Particle motion between two frames of a body at rest, in particle spacings h (per axis, rms):
an MPM block settled on the floor creeps by about this much per frame."""


def rest_jitter(
    x: np.ndarray, h: float, params: SurfaceParams, first, *, device: str | None = None, seed: int = 0
) -> tuple[float, float]:
    """(mean vertex displacement / h between two frames of a body at rest, the same for the very
    same particles surfaced again). x: (n, 3) m; first: the SurfaceResult of x. The second frame
    moves each particle by N(0, REST_NOISE h) per axis. Where both frames have the same triangles
    (the usual case) vertices are compared one to one, else each to the other frame's nearest."""

    def moved(a, b) -> float:
        if a.faces.shape == b.faces.shape and np.array_equal(a.faces, b.faces):
            return float(np.linalg.norm(a.vertices - b.vertices, axis=1).mean() / h)
        if len(a.vertices) == 0 or len(b.vertices) == 0:
            return float("nan")
        d1 = cKDTree(a.vertices).query(b.vertices)[0]
        d2 = cKDTree(b.vertices).query(a.vertices)[0]
        return float((d1.mean() + d2.mean()) / 2 / h)

    dev = wp.get_device(device)
    up = (lambda a: a) if dev.is_cpu else (lambda a: wp.array(a, dtype=wp.vec3, device=dev))
    same = surface_particles(up(x), None, params, device=device).mesh
    noise = np.random.default_rng(seed).normal(0.0, REST_NOISE * h, size=x.shape).astype(np.float32)
    later = surface_particles(up(x + noise), None, params, device=device).mesh
    return moved(first.mesh, later), moved(first.mesh, same)


MOVE_STEP = 0.1
"""How far a slowly moving body travels between two frames, in particle spacings h."""


def moving_jitter(
    x: np.ndarray, h: float, params: SurfaceParams, first, *, device: str | None = None, seed: int = 1
) -> float:
    """Flicker of a slowly moving body: the particles x (m) travel MOVE_STEP h along a fixed
    oblique direction and creep as at rest (REST_NOISE h); returns the mean distance / h of the
    second frame's vertices, moved back, to the first frame's surface (point to the tangent
    plane of the nearest first-frame vertex, so a different triangulation of the same surface
    reads 0). A surfacer that follows the body exactly gives about the rest jitter."""
    a = first.mesh
    if len(a.vertices) == 0:
        return float("nan")
    step = np.array([0.57, 0.41, 0.71]) / np.linalg.norm([0.57, 0.41, 0.71]) * MOVE_STEP * h
    noise = np.random.default_rng(seed).normal(0.0, REST_NOISE * h, size=x.shape)
    dev = wp.get_device(device)
    y = (x + noise + step).astype(np.float32)
    later = surface_particles(
        y if dev.is_cpu else wp.array(y, dtype=wp.vec3, device=dev), None, params, device=device
    ).mesh
    if len(later.vertices) == 0:
        return float("nan")
    back = later.vertices.astype(np.float64) - step
    _, i = cKDTree(a.vertices).query(back)
    off = np.einsum("ij,ij->i", back - a.vertices[i], a.normals[i].astype(np.float64))
    return float(np.abs(off).mean() / h)
