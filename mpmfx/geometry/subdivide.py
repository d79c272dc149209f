"""Catmull-Clark subdivision of polygon meshes (numpy only), for USD meshes authored as
subdivision surfaces: a renderer draws their limit surface, not the control cage, and a
coarse cage can lie well outside it (a cube's cage is a cube; its limit surface a rounded blob
of under half its volume).

Rules as USD's default (OpenSubdiv, interpolateBoundary "edgeAndCorner"): a boundary edge
stays a curve through its own end points (edge point: the midpoint; boundary vertex: 1/8,
6/8, 1/8 of its boundary neighbours and itself), and a boundary vertex of a single face is a
corner and stays. Creases and sharp corners (`Creases`) follow OpenSubdiv's uniform rule. An
edge used by more than two faces is treated as a boundary. tests/geometry/test_subdivide.py
checks it against Blender 4.5's OpenSubdiv (Subdivision Surface modifier, "Keep Corners"): the
same vertices to 2e-7 at levels 1-3, on a cube smooth, creased for good, creased 1.5 and 0.5
and with a sharp corner, and on an open L-shaped grid with a concave boundary corner.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MAX_FACES = 1_000_000
"""Subdivision stops before a level would pass this many faces (an n-gon makes n quads)."""
LEVELS = 3
"""Levels applied: a unit cube's face centre lies 0, 0.061, 0.075, 0.079 inside its cage after
0 to 3 levels and 0.080 on the limit surface, its volume 1, 0.417, 0.350, 0.333 against 0.328:
three levels are within half a percent of the cage's edge."""


@dataclass(frozen=True)
class Creases:
    """Sharpness of a cage's edges and vertices (USD's creaseIndices / cornerIndices, OpenSubdiv's
    uniform crease method): an edge of sharpness s is sharp for floor(s) levels, then blends
    back to smooth (a fraction of it at the level where s < 1), and its halves take s - 1.
    pairs: (k, 2) vertex indices of sharp edges; sharpness: (k,); corners: (c,) vertex indices;
    corner_sharpness: (c,). SHARP_INFINITE or more never wears off."""

    pairs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    sharpness: np.ndarray = field(default_factory=lambda: np.zeros(0))
    corners: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    corner_sharpness: np.ndarray = field(default_factory=lambda: np.zeros(0))


SHARP_INFINITE = 10.0
"""Sharpness from which an edge or corner is sharp at every level (OpenSubdiv's Crease::SHARPNESS_INFINITE)."""


def catmull_clark(
    vertices: np.ndarray,
    counts: np.ndarray,
    indices: np.ndarray,
    *,
    creases: Creases | None = None,
    levels: int = LEVELS,
    max_faces: int = MAX_FACES,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (n', 3) float64, counts (p',) int64, indices, parent (p',) int64: the input
    face each output face came from) after up to `levels` levels of Catmull-Clark subdivision:
    fewer where a level would pass `max_faces` faces (a dense cage is already close to its
    limit surface). vertices: (n, 3); counts: (p,) vertices per face, each at least 3;
    indices: (sum counts,) int, wound as the faces are (kept); creases: sharp edges and
    corners (None: smooth but for the boundary)."""
    v = np.asarray(vertices, float)
    counts = np.asarray(counts, np.int64)
    indices = np.asarray(indices, np.int64)
    creases = creases or Creases()
    parent = np.arange(len(counts))
    for _ in range(levels):
        if counts.sum() > max_faces:  # the next level's quads
            break
        parent = np.repeat(parent, counts)  # an n-gon's n quads, in its corners' order
        v, counts, indices, creases = _level(v, counts, indices, creases)
    return v, counts, indices, parent


def _level(v: np.ndarray, counts: np.ndarray, indices: np.ndarray, creases: Creases):
    """One level: every n-gon becomes n quads (vertex point, edge point, face point, edge point)."""
    nv, nf = len(v), len(counts)
    face = np.repeat(np.arange(nf), counts)  # face of each corner
    start = np.repeat(np.cumsum(counts) - counts, counts)
    pos = np.arange(len(indices)) - start
    size = np.repeat(counts, counts)
    nxt = indices[start + (pos + 1) % size]  # the corner's next vertex
    fpt = np.zeros((nf, 3))
    np.add.at(fpt, face, v[indices])
    fpt /= counts[:, None]
    # edges (corner -> next), undirected
    lo, hi = np.minimum(indices, nxt), np.maximum(indices, nxt)
    edges, edge_of = np.unique(lo * nv + hi, return_inverse=True)
    edge_of = edge_of.ravel()
    ea, eb = edges // nv, edges % nv
    nfaces = np.bincount(edge_of, minlength=len(edges))  # faces at each edge
    fsum = np.zeros((len(edges), 3))
    np.add.at(fsum, edge_of, fpt[face])
    sharp = _edge_sharpness(edges, nv, nfaces, creases)
    mid = 0.5 * (v[ea] + v[eb])
    t = np.minimum(sharp, 1.0)[:, None]  # 1: the sharp rule (the midpoint), 0: smooth, between: a blend
    smooth = np.where(nfaces[:, None] == 2, 0.5 * mid + 0.25 * fsum, mid)  # inside: (a + b + f1 + f2) / 4
    ept = (1.0 - t) * smooth + t * mid
    vpt = _vertex_points(v, indices, face, fpt, ea, eb, nfaces, sharp, creases)
    # corner c of face f: quad (its vertex, edge to next, face point, edge from the previous
    # corner: that corner's edge to next)
    prev_of = edge_of[start + (pos - 1) % size]
    out_v = np.concatenate([vpt, ept, fpt])
    quads = np.stack([indices, nv + edge_of, nv + len(edges) + face, nv + prev_of], axis=1)
    # the halves of a creased edge (its vertex points to its edge point) carry its sharpness less one
    keep = (nfaces == 2) & (sharp > 1.0)
    half = np.flatnonzero(keep)
    child = Creases(
        pairs=np.concatenate([np.stack([ea[half], nv + half], 1), np.stack([eb[half], nv + half], 1)]),
        sharpness=np.tile(_wear(sharp[half]), 2),
        corners=creases.corners[creases.corner_sharpness > 1.0],
        corner_sharpness=_wear(creases.corner_sharpness[creases.corner_sharpness > 1.0]),
    )
    return out_v, np.full(len(quads), 4, np.int64), quads.ravel(), child


def _wear(s: np.ndarray) -> np.ndarray:
    """Sharpness at the next level: s - 1, but infinite stays."""
    return np.where(s >= SHARP_INFINITE, s, s - 1.0)


def _edge_sharpness(edges: np.ndarray, nv: int, nfaces: np.ndarray, creases: Creases) -> np.ndarray:
    """(e,) sharpness of each edge: a boundary (or an edge of more than two faces) infinite,
    a creased edge its sharpness, 0 else."""
    sharp = np.where(nfaces == 2, 0.0, np.inf)
    if len(creases.pairs):
        a, b = creases.pairs[:, 0], creases.pairs[:, 1]
        key = np.minimum(a, b) * nv + np.maximum(a, b)
        at = np.minimum(np.searchsorted(edges, key), len(edges) - 1)
        ok = edges[at] == key  # a crease along no edge of the mesh is ignored
        np.maximum.at(sharp, at[ok], creases.sharpness[ok])
    return sharp


def _vertex_points(v, indices, face, fpt, ea, eb, nfaces, sharp, creases: Creases):
    """New positions of the old vertices: smooth, (Q + 2 R + (n - 3) P) / n (Q: mean of the
    faces' points around, R: of the edges' midpoints, n: edges at the vertex); on a crease or
    boundary, two sharp edges meeting (P 6/8 and the two edges' other ends 1/8 each); a corner
    where three or more sharp edges meet, at a boundary vertex of one face, where a boundary is
    not a simple curve, and at a sharp corner: it stays. A vertex whose sharp edges (or corner)
    wear off this level blends the smooth position in by their mean sharpness below 1."""
    nv = len(v)
    nedge = np.bincount(np.concatenate([ea, eb]), minlength=nv).astype(float)
    nface = np.bincount(indices, minlength=nv).astype(float)
    q = np.zeros((nv, 3))
    np.add.at(q, indices, fpt[face])
    r = np.zeros((nv, 3))
    mid = 0.5 * (v[ea] + v[eb])
    np.add.at(r, ea, mid)
    np.add.at(r, eb, mid)
    n = np.maximum(nedge, 1.0)[:, None]
    out = (q / np.maximum(nface, 1.0)[:, None] + 2.0 * r / n + (n - 3.0) * v) / n
    on = sharp > 0.0
    count = np.bincount(np.concatenate([ea[on], eb[on]]), minlength=nv)
    total = np.bincount(np.concatenate([ea[on], eb[on]]), weights=np.tile(np.minimum(sharp[on], 1.0), 2), minlength=nv)
    t = (total / np.maximum(count, 1))[:, None]  # the sharp edges' mean sharpness, at most 1
    side = np.zeros((nv, 3))
    np.add.at(side, ea[on], v[eb[on]])
    np.add.at(side, eb[on], v[ea[on]])
    crease = count == 2
    out[crease] = ((1.0 - t) * out + t * (0.75 * v + 0.125 * side))[crease]
    corner = count >= 3
    out[corner] = ((1.0 - t) * out + t * v)[corner]
    bnd = nfaces != 2
    nb = np.bincount(np.concatenate([ea[bnd], eb[bnd]]), minlength=nv)
    fixed = ((nb > 0) & (nb != 2)) | ((nb == 2) & (nface == 1)) | (nface == 0)
    out[fixed] = v[fixed]
    if len(creases.corners):
        tc = np.zeros(nv)
        np.maximum.at(tc, creases.corners, np.minimum(creases.corner_sharpness, 1.0))
        out = (1.0 - tc[:, None]) * out + tc[:, None] * v
    return out
