"""Animated test assets authored with pxr: a cube whose points are time-sampled (it grows) or
whose transform is (it moves)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

CUBE = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)  # corner i = 4x + 2y + z bits
QUADS = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]  # wound outward


def growing_cube_usd(
    path: Path, *, centre, half0: float, speed: float, frames, fps: float = 24.0, moving: bool = False
) -> Path:
    """A Y-up stage of a cube about `centre` (m) of half size half0 + speed * t (t = (frame -
    frames[0]) / fps), authored at every frame in `frames` (time code = frame) as time-sampled
    points; moving: instead a rigid cube of half size half0 whose translate is time-sampled
    (centre + (speed t, 0, 0))."""
    from pxr import Gf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(fps)
    xf = UsdGeom.Xform.Define(stage, "/walker")
    mesh = UsdGeom.Mesh.Define(stage, "/walker/body")
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([4] * 6))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([i for q in QUADS for i in q]))
    op = xf.AddTranslateOp() if moving else None
    for f in frames:
        t = (f - frames[0]) / fps
        if moving:
            mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy((CUBE * half0).astype(np.float32)))
            op.Set(Gf.Vec3d(*(np.asarray(centre) + [speed * t, 0, 0])), f)
        else:
            pts = np.asarray(centre) + CUBE * (half0 + speed * t)
            mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)), f)
    stage.GetRootLayer().Save()
    return path
