"""Builds assets/tyre.usda, a lugged tyre that rolls through a bed of mud, and its bed
assets/mud_bed.obj, as a DCC would hand them over: one rigid mesh moved by a time-sampled
transform (translate and rotateZ xformOps), not baked points (CC0).

Run: .venv/bin/python assets/make_tyre.py   (deterministic; metres, Y up, 24 frames a second)

The tyre (a 30 cm carcass, 14 cm wide, with 12 bars of tread 3 cm proud across it: 36 cm
over the tread) rolls along +x about its axle (z) without slip: its axle moves at SPEED and it
turns at SPEED / RADIUS (RADIUS: the tread's outer radius), so the tread in contact stands
still on the ground. Its tread runs SINK below the top of the 12 cm bed (y = BED_TOP), and it
starts clear of the bed's -x end, so it rolls in over the bed's end. Frames 1..36 (1.5 s) are
sampled, every frame.
"""

from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).parent
FRAMES = range(1, 37)
FPS = 24.0
CARCASS = 0.15  # m: the carcass radius; the tread bars stand LUG proud of it
LUG = 0.03  # m: tread height (1.5 grid cells at grid_n 48 in a 1 m domain, so it prints)
RADIUS = CARCASS + LUG  # m: the rolling radius (the tread's outer face)
WIDTH = 0.14  # m: across the tyre (z)
BARS = 12  # tread bars round the tyre, each BAR long round it
BAR = 0.045  # m
BED = (0.72, 0.12, 0.30)  # m: the mud bed's x, y, z extents, its floor on y = 0
BED_X0 = -0.30  # m: the bed's -x end
BED_TOP = BED[1]
SINK = 0.055  # m: how deep the tread runs below the bed's top
SPEED = 0.45  # m/s along +x
START_X = -0.44  # m: the axle's x at frame 1 (the tyre clear of the bed's end face)


def tyre() -> trimesh.Trimesh:
    """The tyre at rest: its axle on the z axis through the origin, a tread bar at the bottom."""
    parts = [trimesh.creation.cylinder(radius=CARCASS, height=WIDTH, sections=64)]
    bar = trimesh.creation.box(extents=[BAR, LUG + 0.01, WIDTH - 0.01])  # 1 cm into the carcass
    bar.apply_translation([0.0, -(RADIUS - (LUG + 0.01) / 2), 0.0])
    for k in range(BARS):
        b = bar.copy()
        b.apply_transform(trimesh.transformations.rotation_matrix(2 * np.pi * k / BARS, [0, 0, 1]))
        parts.append(b)
    return trimesh.boolean.union(parts, engine="manifold")


def pose(frame: float) -> tuple[np.ndarray, float]:
    """(axle position (m), rotation about +z (degrees)) at `frame`: rolling without slip along +x
    turns the tyre clockwise seen from +z, by -x / RADIUS radians."""
    t = (frame - FRAMES[0]) / FPS
    x = START_X + SPEED * t
    return np.array([x, BED_TOP - SINK + RADIUS, 0.0]), -np.degrees(SPEED * t / RADIUS)


def bed() -> trimesh.Trimesh:
    b = trimesh.creation.box(extents=BED)
    b.apply_translation([BED_X0 + BED[0] / 2, BED[1] / 2, 0.0])
    return b


def main():
    from pxr import Gf, Usd, UsdGeom, Vt

    mesh = tyre()
    assert mesh.is_watertight and mesh.volume > 0
    path = HERE / "tyre.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(FPS)
    stage.SetStartTimeCode(FRAMES[0])
    stage.SetEndTimeCode(FRAMES[-1])
    xf = UsdGeom.Xform.Define(stage, "/tyre")
    move, turn = xf.AddTranslateOp(), xf.AddRotateZOp()  # applied rotate first, then translate
    geom = UsdGeom.Mesh.Define(stage, "/tyre/mesh")
    geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    geom.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(mesh.faces)))
    geom.CreateFaceVertexIndicesAttr(Vt.IntArray(mesh.faces.ravel().tolist()))
    geom.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.round(mesh.vertices, 6).astype(np.float32)))
    for f in FRAMES:
        at, angle = pose(f)
        move.Set(Gf.Vec3d(*np.round(at, 6).tolist()), f)
        turn.Set(round(float(angle), 4) + 0.0, f)  # + 0.0: no "-0"
    stage.GetRootLayer().Save()
    print(f"{path.name}: {len(mesh.faces)} faces, {len(FRAMES)} frames")
    mud = bed()
    assert mud.is_watertight
    mud.export(HERE / "mud_bed.obj")
    print(f"mud_bed.obj: {mud.volume * 1e3:.2f} L")


if __name__ == "__main__":
    main()
