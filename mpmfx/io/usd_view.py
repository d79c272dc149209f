"""What a DCC shows of the shot stage beyond its data: the render camera and each surface's
material (UsdPreviewSurface) and display colour; and the prim-name rule. pxr is imported only
inside the functions (as in `mpmfx.io.usd`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

_CAMERA_KEYS = (
    "position",
    "look_at",
    "up",
    "focal_length",
    "horizontal_aperture",
    "vertical_aperture",
    "near",
    "far",
    "focus_distance",
    "f_stop",
)


def check_name(name: str, what: str) -> None:
    from pxr import Sdf, Tf  # backend: pxr

    if not isinstance(name, str) or not Sdf.Path.IsValidIdentifier(name):
        raise ValueError(
            f"{what} name {name!r} is not a valid USD prim name: use letters, digits "
            f"and underscores, not starting with a digit (e.g. "
            f"{Tf.MakeValidIdentifier(str(name))!r})"
        )


def _camera_matrix(position: np.ndarray, look_at: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(4, 4) row-vector camera-to-world matrix: USD cameras look down -Z with +Y up."""
    back = position - look_at
    if np.linalg.norm(back) == 0:
        raise ValueError("camera: position and look_at coincide; move the camera back")
    z = back / np.linalg.norm(back)
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("camera: up is parallel to the view direction; give another 'up'")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3], m[3, :3] = x, y, z, position
    return m


def write_camera(stage: Any, camera: dict, meters_per_unit: float) -> None:
    from pxr import Gf, UsdGeom  # backend: pxr

    unknown = sorted(set(camera) - set(_CAMERA_KEYS))
    if unknown or "position" not in camera or "look_at" not in camera:
        raise ValueError(
            f"camera: needs 'position' and 'look_at' (metres); unknown keys {unknown}; "
            f"allowed: {', '.join(_CAMERA_KEYS)}"
        )
    pos = np.asarray(camera["position"], np.float64).reshape(3)
    target = np.asarray(camera["look_at"], np.float64).reshape(3)
    up = np.asarray(camera.get("up", (0.0, 1.0, 0.0)), np.float64).reshape(3)
    cam = UsdGeom.Camera.Define(stage, "/World/camera")
    cam.MakeMatrixXform().Set(Gf.Matrix4d(_camera_matrix(pos, target, up).tolist()))
    # Lens values are given in mm; UsdGeomCamera wants tenths of a scene unit.
    mm = 1.0 / (100.0 * meters_per_unit)
    focal = float(camera.get("focal_length", 35.0))
    h_ap = float(camera.get("horizontal_aperture", 36.0))
    v_ap = float(camera.get("vertical_aperture", h_ap * 9.0 / 16.0))
    cam.CreateFocalLengthAttr(focal * mm)
    cam.CreateHorizontalApertureAttr(h_ap * mm)
    cam.CreateVerticalApertureAttr(v_ap * mm)
    near, far = float(camera.get("near", 0.01)), float(camera.get("far", 1000.0))
    cam.CreateClippingRangeAttr(Gf.Vec2f(near, far))
    cam.CreateFocusDistanceAttr(float(camera.get("focus_distance", np.linalg.norm(target - pos))))
    cam.CreateFStopAttr(float(camera.get("f_stop", 0.0)))  # 0: no depth of field


@dataclass
class PreviewLook:
    """A surface's material for a DCC: UsdPreviewSurface inputs (linear RGB 0-1, roughness and
    metallic 0-1, opacity 0-1 where 1 is opaque, ior) under the look's name."""

    look: str
    colour: tuple[float, float, float]
    roughness: float = 0.5
    metallic: float = 0.0
    opacity: float = 1.0
    ior: float = 1.5


def bind_look(stage: Any, path: str, look: PreviewLook) -> None:
    """/World/looks/<look> (made once) bound to the mesh at `path`, and its displayColor."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt  # backend: pxr

    check_name(look.look, "look")
    mat_path = f"/World/looks/{look.look}"
    material = UsdShade.Material.Get(stage, mat_path)
    if not material:
        UsdGeom.Scope.Define(stage, "/World/looks")
        material = UsdShade.Material.Define(stage, mat_path)
        shader = UsdShade.Shader.Define(stage, f"{mat_path}/preview")
        shader.CreateIdAttr("UsdPreviewSurface")
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*look.colour))
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(look.roughness))
        shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(float(look.metallic))
        shader.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(float(look.opacity))
        shader.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(float(look.ior))
        material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    prim = stage.OverridePrim(path)
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)
    colour = UsdGeom.PrimvarsAPI(prim).CreatePrimvar(
        "displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.constant
    )
    colour.Set(Vt.Vec3fArray([Gf.Vec3f(*look.colour)]))
