"""What the asset loaders share (mesh, usd_asset, blender_export): the error they raise, the turn
of a Z-up file into our Y-up world, and polygon triangulation. numpy only."""

from __future__ import annotations

import numpy as np

# row vectors times this: a Z-up stage's (x, y, z) becomes (x, z, -y) in our Y-up world
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


class MeshError(ValueError):
    """A mesh cannot be used as given; the message names the file and the fix."""


def fan_triangulate(counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Fan-triangulate polygons. counts: (p,) vertices per face; indices: (sum counts,).

    Returns (t, 3) int64 vertex indices; faces with fewer than 3 vertices are dropped.
    """
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    n_tris = np.clip(counts - 2, 0, None)
    face_start = np.repeat(starts, n_tris)
    # k-th triangle of a face uses vertices (0, k+1, k+2) of that face.
    k = np.arange(n_tris.sum()) - np.repeat(np.cumsum(n_tris) - n_tris, n_tris)
    return np.stack([indices[face_start], indices[face_start + k + 1], indices[face_start + k + 2]], axis=1)
