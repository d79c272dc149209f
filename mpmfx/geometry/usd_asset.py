"""USD assets as a renderer draws them, for mpmfx.geometry.mesh.load_mesh: every
``UsdGeom.Mesh`` under a prim that is drawn (through instanceable references, each instance of a
PointInstancer in place; hidden prims, proxy and guide purposes and hole faces left out), a
subdivision surface as its limit surface with its creases (mpmfx.geometry.subdivide), world
transforms and ``metersPerUnit`` applied, and a Z-up stage (Blender's export) turned Y-up.
pxr is imported inside the functions (a backend boundary: importing this module stays light).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from mpmfx.geometry.common import Z_UP_TO_Y_UP, MeshError, fan_triangulate
from mpmfx.geometry.subdivide import Creases, catmull_clark


def load_usd(path: Path, prim_path: str | None, time_code: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3) float64 metres in our Y-up world, faces (f, 3) int64) of what a renderer
    draws of the stage at `path` under `prim_path` (None: the whole stage) at USD time code
    `time_code` (None: the earliest); MeshError where there is nothing to load."""
    try:
        from pxr import Usd, UsdGeom  # backend: pxr
    except ImportError as exc:  # pragma: no cover - usd-core is a dependency
        raise MeshError(f"{path}: reading USD needs pxr; pip install usd-core") from exc
    stage = Usd.Stage.Open(str(path)) if _usd_readable(path) else None
    if stage is None:
        raise MeshError(f"{path}: cannot be opened as a USD stage; check that the file is valid USD (usdcat can tell)")
    root = stage.GetPrimAtPath(prim_path) if prim_path else stage.GetPseudoRoot()
    if not root or not root.IsValid():
        raise MeshError(
            f"{path}: prim '{prim_path}' not found; pass an existing prim path "
            "(e.g. /root/model) or none to load the whole stage"
        )
    meters = UsdGeom.GetStageMetersPerUnit(stage)
    # Y-up world: a Z-up stage (Blender's USD export) turns -90 degrees about x, (x, y, z) -> (x, z, -y),
    # a rotation, so the winding stands (left as it was, a 1 m post from Blender lay along z)
    up = Z_UP_TO_Y_UP if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z else np.eye(3)
    time = Usd.TimeCode.EarliestTime() if time_code is None else Usd.TimeCode(time_code)
    all_v, all_f, offset = [], [], 0
    for geom, m in _usd_meshes(root, time):
        points = geom.GetPointsAttr().Get(time)
        counts = geom.GetFaceVertexCountsAttr().Get(time)
        indices = geom.GetFaceVertexIndicesAttr().Get(time)
        if points is None or counts is None or indices is None or len(points) == 0:
            continue
        v, counts, indices = _drawn_faces(
            geom,
            np.asarray(points, float),
            np.asarray(counts, np.int64),
            np.asarray(indices, np.int64),
            time,
            where=f"{path}: {geom.GetPath()}",
        )
        v = v @ m[:3, :3] + m[3, :3]
        tris = fan_triangulate(counts, indices)
        if geom.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            tris = tris[:, ::-1]
        if np.linalg.det(m[:3, :3]) < 0:  # a mirroring transform flips the winding
            tris = tris[:, ::-1]
        all_v.append(v @ up * meters)
        all_f.append(tris + offset)
        offset += len(v)
    if not all_f or sum(len(f) for f in all_f) == 0:
        where = f"under '{prim_path}'" if prim_path else "on the stage"
        raise MeshError(
            f"{path}: no UsdGeom.Mesh with faces {where}; point prim_path at "
            "the mesh or export the asset with its geometry"
        )
    return np.concatenate(all_v), np.concatenate(all_f)


def _drawn_faces(geom, v: np.ndarray, counts: np.ndarray, indices: np.ndarray, time, *, where: str):
    """(vertices, counts, indices) of the surface a renderer draws for a UsdGeom.Mesh: its
    faces but those in holeIndices, and for a subdivision surface (subdivisionScheme
    catmullClark, USD's default where none is authored, or loop) the limit surface, closely
    (mpmfx.geometry.subdivide: a coarse cage can lie far outside what is drawn). where: the
    file and prim, for messages."""
    from pxr import UsdGeom  # backend: pxr

    ok = counts >= 3
    if not ok.all():  # points and lines are not faces
        indices = indices[np.repeat(ok, counts)]
        counts = counts[ok]
    keep = np.ones(len(counts), bool)
    holes = geom.GetHoleIndicesAttr().Get(time)
    if holes is not None and len(holes):
        old_index = np.flatnonzero(ok)  # hole indices count the faces as authored
        keep[np.isin(old_index, np.asarray(holes))] = False
    scheme = geom.GetSubdivisionSchemeAttr()
    if scheme.Get() in (UsdGeom.Tokens.catmullClark, UsdGeom.Tokens.loop) and len(counts):
        if not scheme.HasAuthoredValue():  # likely a polygon mesh whose exporter left USD's default
            warnings.warn(
                f"{where}: no subdivisionScheme, so USD's default catmullClark holds and "
                "its limit surface is used, as renderers draw it; for a polygon mesh author "
                'subdivisionScheme = "none"',
                UserWarning,
                stacklevel=2,
            )
        v, counts, indices, parent = catmull_clark(v, counts, indices, creases=_usd_creases(geom, time, where))
        keep = keep[parent]
    if not keep.all():
        indices = indices[np.repeat(keep, counts)]
        counts = counts[keep]
    return v, counts, indices


def _usd_creases(geom, time, where: str):
    """The mesh's authored creases (chains of vertices, a sharpness per chain or per edge) and
    sharp corners, as mpmfx.geometry.subdivide.Creases; where: the file and prim, for messages."""

    def get(attr, dtype):
        value = attr.Get(time)
        return np.zeros(0, dtype) if value is None else np.asarray(value, dtype)

    chain = get(geom.GetCreaseIndicesAttr(), np.int64)
    lengths = get(geom.GetCreaseLengthsAttr(), np.int64)
    sharp = get(geom.GetCreaseSharpnessesAttr(), float)
    starts = np.cumsum(lengths) - lengths
    a = np.concatenate([chain[s : s + n - 1] for s, n in zip(starts, lengths)] or [np.zeros(0, np.int64)])
    b = np.concatenate([chain[s + 1 : s + n] for s, n in zip(starts, lengths)] or [np.zeros(0, np.int64)])
    if len(sharp) == len(lengths):  # one sharpness a crease, else one an edge
        sharp = np.repeat(sharp, np.maximum(lengths - 1, 0))
    if len(sharp) != len(a):
        raise MeshError(
            f"{where}: creaseSharpnesses holds {len(sharp)} values for {len(lengths)} creases of "
            f"{len(a)} edges; give one a crease or one an edge"
        )
    corners = get(geom.GetCornerIndicesAttr(), np.int64)
    corner_sharp = get(geom.GetCornerSharpnessesAttr(), float)
    if len(corner_sharp) != len(corners):
        raise MeshError(
            f"{where}: {len(corners)} cornerIndices but {len(corner_sharp)} cornerSharpnesses; "
            "give one sharpness a corner"
        )
    return Creases(pairs=np.stack([a, b], 1), sharpness=sharp, corners=corners, corner_sharpness=corner_sharp)


def _usd_meshes(root, time, *, place=None):
    """(UsdGeom.Mesh, (4, 4) float64 local-to-world matrix for row vectors) of every mesh a
    renderer would draw under ``root``: through instanceable references (instance proxies),
    each instance of a PointInstancer's prototypes at its own transform, and without what is
    hidden or drawn only in viewports (visibility invisible, purpose guide or proxy: a
    production asset's proxy is a coarse double of its render geometry). place: (4, 4) matrix
    taking world space to where it is instanced (a prototype's meshes), or None."""
    from pxr import Usd, UsdGeom  # backend: pxr

    cache = UsdGeom.XformCache(time)
    it = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies()))
    for prim in it:
        img = UsdGeom.Imageable(prim)
        if img and (
            img.ComputeVisibility(time) == UsdGeom.Tokens.invisible
            or img.ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy)
        ):
            it.PruneChildren()
            continue
        world = np.array(cache.GetLocalToWorldTransform(prim), dtype=float).reshape(4, 4)
        if place is not None:
            world = world @ place
        if prim.IsA(UsdGeom.PointInstancer):
            it.PruneChildren()  # the prototypes are drawn only where instanced
            yield from _instanced_meshes(UsdGeom.PointInstancer(prim), world, time)
        elif prim.IsA(UsdGeom.Mesh):
            yield UsdGeom.Mesh(prim), world


def _instanced_meshes(instancer, world: np.ndarray, time):
    """_usd_meshes of each drawn instance (not in invisibleIds nor inactiveIds) of a
    PointInstancer whose local-to-world matrix is `world`: a prototype's mesh at (mesh relative
    to the prototype) x (the instance's transform, which holds the prototype's own) x world."""
    from pxr import UsdGeom  # backend: pxr

    protos = instancer.GetPrototypesRel().GetTargets()
    index = instancer.GetProtoIndicesAttr().Get(time)
    if not protos or index is None:
        return
    stage = instancer.GetPrim().GetStage()
    cache = UsdGeom.XformCache(time)
    # every instance's transform, in protoIndices' order (applying the mask would drop the hidden
    # ones from the list and shift the rest against protoIndices), then the mask by hand
    inst = [
        np.array(m, dtype=float).reshape(4, 4)
        for m in instancer.ComputeInstanceTransformsAtTime(
            time, time, UsdGeom.PointInstancer.IncludeProtoXform, UsdGeom.PointInstancer.IgnoreMask
        )
    ]
    shown = np.asarray(instancer.ComputeMaskAtTime(time), bool)  # empty: every instance is drawn
    index = np.asarray(index)
    drawn = shown if len(shown) == len(index) else np.ones(len(index), bool)
    for k, path in enumerate(protos):
        proto = stage.GetPrimAtPath(path)
        if not proto:
            continue
        # world space -> the prototype's own space (its transform comes back in the instance's)
        to_proto = np.linalg.inv(np.array(cache.GetLocalToWorldTransform(proto), dtype=float).reshape(4, 4))
        for i in np.flatnonzero((index == k) & drawn):
            yield from _usd_meshes(proto, time, place=to_proto @ inst[i] @ world)


def _usd_readable(path: Path) -> bool:
    # Usd.Stage.Open raises (rather than returning None) on garbage; normalise to a bool.
    from pxr import Sdf  # backend: pxr

    try:
        return Sdf.Layer.FindOrOpen(str(path)) is not None
    except Exception:
        return False
