"""Inside/outside and signed distance of a triangle mesh on a regular lattice.

A lattice is ``origin + index * h``: origin (3,) metres, spacing h metres, shape (nx, ny, nz).
Vectorised numpy only (no BVH): inside tests cast one ray per lattice column and count signed
crossings, which is the integer winding number of a closed, consistently oriented mesh (so
overlapping, self-intersecting parts count as inside too). Open meshes vote over the three
axes and settle disagreements with the generalized winding number (Jacobson et al. 2013),
computed exactly but without summing over every triangle: the mesh plus caps over its holes is
closed, so its winding number is the signed ray count, and the open mesh's is that count less
the caps' own (`open_winding_number`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from trimesh.triangles import closest_point

# Every lattice point is tested as if moved by this tiny, irrational fraction of h, so a
# ray never passes exactly through a mesh edge or vertex, and a point on an axis-aligned
# face is decided the same way in every column (not by floating-point noise).
_RAY_SHIFT = np.array([1.2345678e-6, 2.3456789e-6, 3.4567891e-6])
_CHUNK = 2_000_000  # work items per numpy chunk: bounds peak memory to ~100s of MB


@dataclass(frozen=True)
class Lattice:
    """Regular lattice of points ``origin + index * h``.

    origin: (3,) float64 metres, position of index (0, 0, 0). h: spacing in metres.
    shape: (3,) number of points per axis.
    """

    origin: np.ndarray
    h: float
    shape: tuple[int, int, int]

    def points(self, index: np.ndarray) -> np.ndarray:
        """World positions (n, 3) float64 of integer indices (n, 3)."""
        return self.origin + np.asarray(index, float) * self.h


def open_edge_fraction(mesh) -> float:
    """Fraction of the mesh's unique edges that are not shared by exactly two faces."""
    edges = np.asarray(mesh.edges_sorted)
    if len(edges) == 0:
        return 1.0
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return float(np.mean(counts != 2))


def inside_mask(mesh, lattice: Lattice) -> np.ndarray:
    """Boolean (nx, ny, nz): lattice point lies inside ``mesh``.

    Watertight meshes: signed ray crossings along z (winding number > 0). Other meshes:
    majority vote of rays along x, y and z; points where the rays disagree (near holes)
    get the generalized winding number, inside where it is >= 0.5.
    """
    signed = bool(mesh.is_winding_consistent)
    if mesh.is_watertight and signed:
        return ray_winding(mesh, lattice, axis=2, signed=True) > 0
    votes = [_ray_inside(mesh, lattice, axis, signed) for axis in range(3)]
    count = votes[0].astype(np.int8) + votes[1] + votes[2]
    inside = count >= 2
    unsure = (count == 1) | (count == 2)
    if unsure.any():
        idx = np.argwhere(unsure)
        gwn = open_winding_number(mesh, lattice, idx)
        inside[tuple(idx.T)] = np.abs(gwn) >= 0.5
    return inside


def _ray_inside(mesh, lattice: Lattice, axis: int, signed: bool) -> np.ndarray:
    w = ray_winding(mesh, lattice, axis=axis, signed=signed)
    return w > 0 if signed else (w % 2) == 1


def ray_winding(mesh, lattice: Lattice, *, axis: int, signed: bool) -> np.ndarray:
    """Crossing count (nx, ny, nz) int32 of a ray from -inf along ``axis`` to each point.

    signed: count +1 entering / -1 leaving (outward normals), else +1 per crossing.
    """
    return _ray_crossings(
        np.asarray(mesh.triangles, float), np.asarray(mesh.face_normals, float), lattice, axis=axis, signed=signed
    )


def _ray_crossings(tris: np.ndarray, normals: np.ndarray, lattice: Lattice, *, axis: int, signed: bool) -> np.ndarray:
    """ray_winding of triangles tris (f, 3, 3) metres with normals (f, 3) (only their signs
    along ``axis`` are read: the direction the vertex order winds)."""
    u, v = [a for a in range(3) if a != axis]
    # Index-space coordinates: lattice point i sits at i (+ the ray shift on u, v).
    t = (tris - lattice.origin) / lattice.h
    t[:, :, u] -= _RAY_SHIFT[u]
    t[:, :, v] -= _RAY_SHIFT[v]
    shape = lattice.shape
    acc = np.zeros((shape[u], shape[v], shape[axis] + 1), np.int32)
    sign_all = -np.sign(normals[:, axis]) if signed else np.ones(len(tris))
    for tri_ids, iu, iv in _columns_per_triangle(t[:, :, u], t[:, :, v], shape[u], shape[v]):
        a_hit, ok = _project_hits(t[tri_ids], iu, iv, u, v, axis)
        k = np.clip(np.ceil(a_hit[ok] - _RAY_SHIFT[axis]), 0, shape[axis]).astype(np.int64)
        np.add.at(acc, (iu[ok], iv[ok], k), sign_all[tri_ids[ok]].astype(np.int32))
    w = np.cumsum(acc, axis=2, dtype=np.int32)[:, :, : shape[axis]]
    return np.moveaxis(w, 2, axis)


def _columns_per_triangle(tu, tv, nu, nv):
    """Yield (tri_ids, iu, iv) chunks: every lattice column inside each triangle's 2D bbox."""
    lo_u = np.clip(np.ceil(tu.min(1)), 0, None).astype(np.int64)
    hi_u = np.clip(np.floor(tu.max(1)), None, nu - 1).astype(np.int64)
    lo_v = np.clip(np.ceil(tv.min(1)), 0, None).astype(np.int64)
    hi_v = np.clip(np.floor(tv.max(1)), None, nv - 1).astype(np.int64)
    cu = np.clip(hi_u - lo_u + 1, 0, None)
    cv = np.clip(hi_v - lo_v + 1, 0, None)
    yield from _expand_boxes(np.stack([lo_u, lo_v], 1), np.stack([cu, cv], 1))


def _expand_boxes(lo: np.ndarray, counts: np.ndarray):
    """Yield (box_ids, i0, i1, ...) chunks enumerating every index in each integer box.

    lo, counts: (b, d) int64 box corners and sizes. Chunks hold at most ~_CHUNK items.
    """
    per_box = np.prod(counts, axis=1)
    ends = np.cumsum(per_box)
    start = 0
    while start < len(per_box):
        base = ends[start - 1] if start else 0
        stop = max(int(np.searchsorted(ends, base + _CHUNK, side="right")), start + 1)
        ids = np.arange(start, stop)
        n = per_box[start:stop]
        box = np.repeat(ids, n)
        local = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        out = []
        for d in range(lo.shape[1] - 1, -1, -1):  # last axis fastest
            c = counts[box, d]
            out.append(lo[box, d] + local % c)
            local = local // c
        yield (box, *out[::-1])
        start = stop


def _project_hits(t, iu, iv, u, v, axis):
    """Where the column (iu, iv) crosses each triangle t (m, 3, 3) in index space.

    Returns (a_hit (m,), ok (m,) bool): the axis coordinate of the hit, and whether the
    column passes through the triangle's interior.
    """
    pu, pv = iu.astype(float), iv.astype(float)
    a_u, a_v = t[:, 0, u], t[:, 0, v]
    b_u, b_v = t[:, 1, u], t[:, 1, v]
    c_u, c_v = t[:, 2, u], t[:, 2, v]
    # Edge functions: twice the signed areas of the sub-triangles opposite each vertex.
    wa = (b_u - pu) * (c_v - pv) - (b_v - pv) * (c_u - pu)
    wb = (c_u - pu) * (a_v - pv) - (c_v - pv) * (a_u - pu)
    wc = (a_u - pu) * (b_v - pv) - (a_v - pv) * (b_u - pu)
    area = wa + wb + wc
    ok = (area != 0) & (((wa >= 0) & (wb >= 0) & (wc >= 0)) | ((wa <= 0) & (wb <= 0) & (wc <= 0)))
    safe = np.where(area == 0, 1.0, area)
    a_hit = (wa * t[:, 0, axis] + wb * t[:, 1, axis] + wc * t[:, 2, axis]) / safe
    return a_hit, ok


def boundary_caps(mesh) -> np.ndarray:
    """Triangles (c, 3, 3) float64 metres that close ``mesh``: a fan over each loop of its
    boundary, from the mean of the loop's vertices, wound so that the mesh and the caps
    together have no boundary (every edge is used as often in each direction). The boundary
    is taken as a chain: an edge counts with the net number of times the faces use it
    a -> b rather than b -> a, so holes, non-manifold edges and faces wound against their
    neighbours all get capped. (0, 3, 3) for a closed, consistently wound mesh."""
    faces = np.asarray(mesh.faces, np.int64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    lo, hi = e.min(axis=1), e.max(axis=1)
    pairs, inv = np.unique(np.stack([lo, hi], 1), axis=0, return_inverse=True)
    net = np.bincount(inv.ravel(), weights=np.where(e[:, 0] < e[:, 1], 1, -1), minlength=len(pairs)).astype(np.int64)
    keep = net != 0
    if not keep.any():
        return np.zeros((0, 3, 3))
    pairs, net = pairs[keep], net[keep]
    # each boundary edge as a -> b, repeated as often as the faces leave it unmatched
    a = np.repeat(np.where(net > 0, pairs[:, 0], pairs[:, 1]), np.abs(net))
    b = np.repeat(np.where(net > 0, pairs[:, 1], pairs[:, 0]), np.abs(net))
    verts = np.asarray(mesh.vertices, float)
    used, local = np.unique(np.concatenate([a, b]), return_inverse=True)
    m = len(used)
    graph = coo_matrix((np.ones(len(a)), (local[: len(a)], local[len(a) :])), shape=(m, m))
    _, loop = connected_components(graph, directed=False)
    apex = np.zeros((loop.max() + 1, 3))
    np.add.at(apex, loop, verts[used])
    apex /= np.bincount(loop)[:, None]
    # the cap of edge a -> b is (b, a, apex): its edges b -> a cancel the mesh's a -> b, and the
    # edges to the apex cancel between neighbours (each boundary vertex is entered as often as left)
    return np.stack([verts[b], verts[a], apex[loop[local[: len(a)]]]], axis=1)


def open_winding_number(mesh, lattice: Lattice, index: np.ndarray) -> np.ndarray:
    """Generalized winding number (n,) of ``mesh`` at the lattice points ``index`` (n, 3) int,
    equal to ``winding_number(mesh.triangles, points)`` without its cost per triangle (a
    500k-triangle asset with holes spent minutes in it). The mesh and its boundary_caps are
    closed, so their winding number is an integer, the signed ray count along z (exact: two
    triangles that share an edge see it with opposite signs, to the bit); the winding number
    is linear in the triangles, so the mesh's own is that count less the caps'. Like the ray
    tests, it is taken at each point moved by _RAY_SHIFT, so a point on an axis-aligned face
    (or on a flat patch and its coplanar cap) is decided as the rays decide it."""
    caps = boundary_caps(mesh)
    points = lattice.points(index) + _RAY_SHIFT * lattice.h
    if len(caps) >= len(mesh.faces):  # faces wound every which way: the caps would cost more than they save
        return winding_number(np.asarray(mesh.triangles, float), points)
    tris = np.concatenate([np.asarray(mesh.triangles, float), caps])
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    closed = _ray_crossings(tris, normals, lattice, axis=2, signed=True)
    return closed[tuple(np.asarray(index).T)] - winding_number(caps, points)


def winding_number(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Generalized winding number (n,) of points (n, 3) w.r.t. triangles (f, 3, 3).

    Sum of signed solid angles / 4 pi (Van Oosterom & Strackee); 1 inside a closed
    outward-oriented surface, 0 outside, fractional near holes. O(n f), chunked.
    """
    out = np.empty(len(points))
    step = max(1, _CHUNK // max(1, len(triangles)))
    for s in range(0, len(points), step):
        p = points[s : s + step, None, None, :]
        d = triangles[None, :, :, :] - p  # (m, f, 3, 3)
        a, b, c = d[:, :, 0], d[:, :, 1], d[:, :, 2]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        det = np.einsum("mfi,mfi->mf", a, np.cross(b, c))
        den = (
            la * lb * lc
            + np.einsum("mfi,mfi->mf", a, b) * lc
            + np.einsum("mfi,mfi->mf", b, c) * la
            + np.einsum("mfi,mfi->mf", c, a) * lb
        )
        out[s : s + step] = np.arctan2(det, den).sum(axis=1) / (2.0 * np.pi)
    return out


def signed_distance(mesh, lattice: Lattice, inside: np.ndarray) -> np.ndarray:
    """Signed distance (nx, ny, nz) float32 metres, negative inside.

    Exact (closest point on the triangles) within one lattice spacing of the surface;
    further away, the distance to the nearest exact point plus that point's distance,
    an upper bound that is within about one spacing of the truth.
    """
    h, shape = lattice.h, lattice.shape
    tris = np.asarray(mesh.triangles, float)
    dist = np.full(int(np.prod(shape)), np.inf)
    t = (tris - lattice.origin) / h
    lo = np.clip(np.ceil(t.min(1) - 1.0), 0, None).astype(np.int64)
    hi = np.minimum(np.floor(t.max(1) + 1.0), np.array(shape) - 1).astype(np.int64)
    counts = np.clip(hi - lo + 1, 0, None)
    for tri_ids, i, j, k in _expand_boxes(lo, counts):
        p = lattice.origin + np.stack([i, j, k], 1) * h
        d = np.linalg.norm(closest_point(tris[tri_ids], p) - p, axis=1)
        np.minimum.at(dist, np.ravel_multi_index((i, j, k), shape), d)
    dist = dist.reshape(shape)
    known = dist <= h
    if not known.all():
        edt, idx = ndimage.distance_transform_edt(~known, sampling=h, return_indices=True)
        far = edt + dist[tuple(idx)]
        dist = np.where(known, dist, far)
    return np.where(inside, -dist, dist).astype(np.float32)
