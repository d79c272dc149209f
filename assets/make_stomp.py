"""Builds assets/stomp_boot.usda: a boot-like block that stomps into a snow bed and lifts, as a
DCC would hand it over after baking a rig: time-sampled points in world space (CC0).

Run: .venv/bin/python assets/make_stomp.py   (deterministic; metres, Y up, 24 frames a second)

The boot (a 10 x 7 x 20 cm foot, its sole rounded up at heel and toe, and a 9 x 9 cm shaft 25 cm
tall over the heel, so the snow it displaces does not spill over it) comes down heel first,
rolls flat as it presses (frames 6-14) 6 cm into the 12 cm bed of assets/snow_bed.obj (top at y = 0.12 m),
holds, and lifts heel first with a toe-off roll. Frames 1..36 (1.5 s) are sampled, every frame.
"""

from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).parent
FRAMES = range(1, 37)
# (frame, sole height at the ball of the foot (m), roll about x (degrees; + lifts the toe))
KEYS = [
    (1, 0.26, 12.0),
    (6, 0.24, 12.0),
    (14, 0.06, 0.0),
    (20, 0.06, 0.0),
    (26, 0.12, -15.0),
    (32, 0.30, -5.0),
    (36, 0.30, 0.0),
]


def boot() -> trimesh.Trimesh:
    """The boot at rest, its sole on y = 0, the ball of the foot at the origin, toe along +z."""
    b = trimesh.creation.box(extents=[0.10, 0.07, 0.20])
    b = b.subdivide().subdivide()  # vertices along the sole, so the rounded heel and toe bend it
    v = b.vertices.copy()
    v[:, 1] += 0.035
    end = np.clip((np.abs(v[:, 2]) - 0.06) / 0.04, 0.0, 1.0)  # 0 under the arch, 1 at heel and toe
    low = v[:, 1] < 1e-6
    v[low, 1] += 0.02 * end[low] ** 2  # round the sole up at both ends
    foot = trimesh.Trimesh(v, b.faces, process=False)
    shaft = trimesh.creation.box(extents=[0.09, 0.25, 0.09])
    shaft.apply_translation([0.0, 0.05 + 0.125, -0.05])
    out = trimesh.boolean.union([foot, shaft], engine="manifold")
    out.apply_translation([0.0, 0.0, 0.03])  # the ball of the foot (the roll's pivot) 3 cm behind the middle
    return out


def pose(frame: float) -> tuple[float, float]:
    """(height, roll) at `frame`: smoothstep between the KEYS."""
    f = [k[0] for k in KEYS]
    i = min(max(np.searchsorted(f, frame, side="right") - 1, 0), len(KEYS) - 2)
    a = np.clip((frame - f[i]) / (f[i + 1] - f[i]), 0.0, 1.0)
    s = a * a * (3 - 2 * a)
    return tuple((1 - s) * np.array(KEYS[i][1:]) + s * np.array(KEYS[i + 1][1:]))


def points_at(mesh: trimesh.Trimesh, frame: float) -> np.ndarray:
    h, roll = pose(frame)
    r = np.radians(roll)
    rot = np.array([[1, 0, 0], [0, np.cos(r), np.sin(r)], [0, -np.sin(r), np.cos(r)]])  # + lifts +z (the toe)
    return mesh.vertices @ rot.T + [0.0, h, 0.0]


def main():
    from pxr import Usd, UsdGeom, Vt

    mesh = boot()
    assert mesh.is_watertight and mesh.volume > 0
    path = HERE / "stomp_boot.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(24)
    stage.SetStartTimeCode(FRAMES[0])
    stage.SetEndTimeCode(FRAMES[-1])
    UsdGeom.Xform.Define(stage, "/boot")
    geom = UsdGeom.Mesh.Define(stage, "/boot/mesh")
    geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    geom.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(mesh.faces)))
    geom.CreateFaceVertexIndicesAttr(Vt.IntArray(mesh.faces.ravel().tolist()))
    for f in FRAMES:
        pts = np.round(points_at(mesh, f), 6).astype(np.float32)
        geom.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts), f)
    stage.GetRootLayer().Save()
    print(f"{path.name}: {len(mesh.faces)} faces, {len(FRAMES)} frames")


if __name__ == "__main__":
    main()
