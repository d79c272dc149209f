"""USD export: one binary crate layer per frame, stitched into a shot stage with value clips.

Layout on disk (all paths relative to the root stage's folder)::

    shot.usda                 root: stage metadata, clip metadata on /World, camera
    shot.topology.usdc        every prim and static property of the frames, no time samples
    shot.manifest.usda        which attributes the clips hold time samples for
    frames/NNNN.usdc          one frame: time samples at time code = frame

Prims (names from the caller; world units are metres, Y up, exactly as the arrays came in)::

    /World                    Xform; carries the unit / up-axis correction if the stage is not m, Y
    /World/<name>/particles   UsdGeomPoints  (points, velocities, widths, ids, primvars:*)
    /World/<name>/mesh        UsdGeomMesh    (points, triangles, normals, velocities)
    /World/<name>/volume      UsdVolVolume, field:<field> -> /World/<name>/volume/<field>
                              (UsdVolOpenVDBAsset, filePath time-sampled per frame)
    /World/colliders/<name>   UsdGeomMesh, static local geometry, animated xformOp:transform
    /World/camera             UsdGeomCamera (if finalize is given one)

The root opens without touching any frame file: USD opens a clip only when one of its values
is read, so the cost of opening grows with the clip list (a few bytes a frame), not the data.
pxr (usd-core) is imported only inside the functions that need it.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mpmfx.cache import atomic_path

INSTALL_HINT = (
    "pxr (usd-core) is not importable: run `bash setup.sh`, or "
    "`pip install usd-core` in the environment that runs mpmfx"
)

RESERVED_NAMES = ("colliders", "camera")
# Known VDB fields: fieldClass, fieldDataType, vectorDataRoleHint (None = not authored).
_FIELD_KINDS = {
    "surface": ("levelSet", "float", None),
    "density": ("fogVolume", "float", None),
    "vel": ("unknown", "float3", "Vector"),
}
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


def import_pxr() -> Any:
    """Return the pxr package with the modules used here loaded, or raise ImportError saying
    how to install it."""
    try:
        import pxr  # backend: pxr
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdUtils, UsdVol, Vt  # backend: pxr  # noqa: F401
    except ImportError as exc:
        raise ImportError(INSTALL_HINT) from exc
    return pxr


@dataclass
class PointsSample:
    """Particles of one object at one frame.

    positions: (n, 3) float32, metres, world.   velocities: (n, 3) float32, metres/second.
    widths: (n,) float32 particle diameters, metres; or one float for all particles (stored
        once, constant interpolation). Use the same form on every frame of a shot.
    ids: (n,) int64 persistent particle ids.   primvars: name -> (n,) or (n, 3) array
    (e.g. material (n,) int32, body (n,) int32, Jp (n,) float32), vertex interpolation.
    """

    positions: np.ndarray
    velocities: np.ndarray | None = None
    widths: np.ndarray | float | None = None
    ids: np.ndarray | None = None
    primvars: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class MeshSample:
    """A triangle surface at one frame.

    points: (m, 3) float32 metres; face_vertex_indices: (k, 3) int32 triangles (right-handed,
    outward normals); normals: (m, 3) float32 unit vertex normals; velocities: (m, 3) float32 m/s.
    """

    points: np.ndarray
    face_vertex_indices: np.ndarray
    normals: np.ndarray | None = None
    velocities: np.ndarray | None = None


@dataclass
class ColliderSample:
    """A rigid collider at one frame.

    points: (m, 3) float32 metres in the collider's local frame (the same every frame);
    faces: (k, 3) int32 triangles; xform: (4, 4) float64 local-to-world at this frame in the
    column-vector convention (world = xform @ [p, 1]; translation in xform[:3, 3]).
    animated: the points change from frame to frame (a deforming collider): written as time
    samples, not as the static default.
    """

    name: str
    points: np.ndarray
    faces: np.ndarray
    xform: np.ndarray
    animated: bool = False


@contextlib.contextmanager
def _atomic_target(path: Path) -> Iterator[Path]:
    """`mpmfx.cache.atomic_path` (the layer is read back before the rename), then reload a
    layer this process already holds for `path`."""
    from pxr import Sdf  # backend: pxr

    readable = lambda tmp: Sdf.Layer.OpenAsAnonymous(str(tmp)) is not None  # noqa: E731
    with atomic_path(path, verify=readable, checksum=True) as tmp:
        yield tmp
    _reload_if_open(path)


def _reload_if_open(path: Path) -> None:
    """A layer this process already opened from `path` would keep serving the old content."""
    from pxr import Sdf  # backend: pxr

    layer = Sdf.Layer.Find(str(path))
    if layer is not None:
        layer.Reload(True)


def _export_layer(layer: Any, path: Path) -> None:
    with _atomic_target(path) as tmp:
        if not layer.Export(str(tmp)):
            raise OSError(f"{path}: USD could not write the layer (disk full or no permission?)")


def _array(value: Any, where: str, *, shape: tuple[int | None, ...], dtype: type) -> np.ndarray:
    """Check `value` against `shape` (None = any length) and return it C-contiguous in `dtype`."""
    arr = np.asarray(value)
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{where}: shape {arr.shape}, expected {want}")
    if np.issubdtype(arr.dtype, np.floating) and not np.isfinite(arr).all():
        raise ValueError(f"{where}: contains NaN or inf; the upstream stage produced invalid values")
    return np.ascontiguousarray(arr, dtype=dtype)


def _check_name(name: str, what: str) -> None:
    from pxr import Sdf, Tf  # backend: pxr

    if not isinstance(name, str) or not Sdf.Path.IsValidIdentifier(name):
        raise ValueError(
            f"{what} name {name!r} is not a valid USD prim name: use letters, digits "
            f"and underscores, not starting with a digit (e.g. "
            f"{Tf.MakeValidIdentifier(str(name))!r})"
        )
    if name in RESERVED_NAMES and what != "collider":
        raise ValueError(f"{what} name {name!r} is reserved in /World; rename the object")


def _extent(points: np.ndarray, pad: float = 0.0) -> Any:
    from pxr import Vt  # backend: pxr

    if len(points) == 0:
        return Vt.Vec3fArray.FromNumpy(np.zeros((2, 3), np.float32))
    box = np.stack([points.min(axis=0) - pad, points.max(axis=0) + pad]).astype(np.float32)
    return Vt.Vec3fArray.FromNumpy(box)


def _vt_array(arr: np.ndarray, where: str) -> tuple[Any, Any]:
    """(Sdf value type, Vt array) for a primvar array of shape (n,) or (n, 3)."""
    from pxr import Sdf, Vt  # backend: pxr

    kinds = {
        (1, "i4"): (Sdf.ValueTypeNames.IntArray, Vt.IntArray, np.int32),
        (1, "i8"): (Sdf.ValueTypeNames.Int64Array, Vt.Int64Array, np.int64),
        (1, "f4"): (Sdf.ValueTypeNames.FloatArray, Vt.FloatArray, np.float32),
        (1, "f8"): (Sdf.ValueTypeNames.FloatArray, Vt.FloatArray, np.float32),
        (2, "f4"): (Sdf.ValueTypeNames.Float3Array, Vt.Vec3fArray, np.float32),
        (2, "f8"): (Sdf.ValueTypeNames.Float3Array, Vt.Vec3fArray, np.float32),
    }
    key = (arr.ndim, arr.dtype.str[1:]) if arr.dtype.kind in "if" else None
    if key not in kinds or (arr.ndim == 2 and arr.shape[1] != 3):
        raise ValueError(
            f"{where}: dtype {arr.dtype} shape {arr.shape} is not supported; use "
            f"(n,) int32/int64/float32 or (n, 3) float32"
        )
    type_name, vt_type, dtype = kinds[key]
    return type_name, vt_type.FromNumpy(np.ascontiguousarray(arr, dtype=dtype))


def _write_points(stage: Any, path: str, sample: PointsSample, time: float, where: str) -> None:
    from pxr import UsdGeom, Vt  # backend: pxr

    pts = _array(sample.positions, f"{where}.positions", shape=(None, 3), dtype=np.float32)
    n = len(pts)
    prim = UsdGeom.Points.Define(stage, path)
    prim.CreatePointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts), time)
    pad = 0.0
    if sample.velocities is not None:
        vel = _array(sample.velocities, f"{where}.velocities", shape=(n, 3), dtype=np.float32)
        prim.CreateVelocitiesAttr().Set(Vt.Vec3fArray.FromNumpy(vel), time)
    if sample.widths is not None:
        # Interpolation is metadata, one value for the whole shot (the topology layer keeps the
        # first frame's): a scalar width means constant, an array means vertex, on every frame.
        if np.ndim(sample.widths) == 0:
            widths = _array(np.reshape(sample.widths, 1), f"{where}.widths", shape=(1,), dtype=np.float32)
            prim.SetWidthsInterpolation(UsdGeom.Tokens.constant)
        else:
            widths = _array(sample.widths, f"{where}.widths", shape=(n,), dtype=np.float32)
            prim.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
        pad = float(widths.max()) / 2 if len(widths) else 0.0
        prim.CreateWidthsAttr().Set(Vt.FloatArray.FromNumpy(widths), time)
    if sample.ids is not None:
        ids = _array(sample.ids, f"{where}.ids", shape=(n,), dtype=np.int64)
        prim.CreateIdsAttr().Set(Vt.Int64Array.FromNumpy(ids), time)
    api = UsdGeom.PrimvarsAPI(prim)
    for name, values in sample.primvars.items():
        _check_name(name, f"{where} primvar")
        arr = np.asarray(values)
        if len(arr) != n:
            raise ValueError(f"{where}.primvars[{name!r}]: length {len(arr)}, expected {n} (one value per particle)")
        type_name, vt = _vt_array(arr, f"{where}.primvars[{name!r}]")
        api.CreatePrimvar(name, type_name, UsdGeom.Tokens.vertex).Set(vt, time)
    prim.CreateExtentAttr().Set(_extent(pts, pad), time)


def _write_mesh(stage: Any, path: str, sample: MeshSample, time: float, where: str) -> None:
    from pxr import UsdGeom, Vt  # backend: pxr

    pts = _array(sample.points, f"{where}.points", shape=(None, 3), dtype=np.float32)
    tris = _array(sample.face_vertex_indices, f"{where}.face_vertex_indices", shape=(None, 3), dtype=np.int32)
    if tris.size and (tris.min() < 0 or tris.max() >= len(pts)):
        raise ValueError(f"{where}.face_vertex_indices: indices must lie in [0, {len(pts)})")
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreatePointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts), time)
    mesh.CreateFaceVertexCountsAttr().Set(Vt.IntArray.FromNumpy(np.full(len(tris), 3, np.int32)), time)
    mesh.CreateFaceVertexIndicesAttr().Set(Vt.IntArray.FromNumpy(tris.reshape(-1)), time)
    if sample.normals is not None:
        nrm = _array(sample.normals, f"{where}.normals", shape=(len(pts), 3), dtype=np.float32)
        mesh.CreateNormalsAttr().Set(Vt.Vec3fArray.FromNumpy(nrm), time)
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    if sample.velocities is not None:
        vel = _array(sample.velocities, f"{where}.velocities", shape=(len(pts), 3), dtype=np.float32)
        mesh.CreateVelocitiesAttr().Set(Vt.Vec3fArray.FromNumpy(vel), time)
    mesh.CreateExtentAttr().Set(_extent(pts), time)


def _write_volume(
    stage: Any, path: str, fields: dict[str, str], time: float, *, root_dir: Path, layer_dir: Path, where: str
) -> None:
    from pxr import Sdf, UsdVol  # backend: pxr

    volume = UsdVol.Volume.Define(stage, path)
    for name, file_path in fields.items():
        _check_name(name, f"{where} field")
        target = Path(file_path)
        if target.suffix != ".vdb":
            raise ValueError(f"{where}[{name!r}]: {file_path!r} is not a .vdb file")
        # The caller names files relative to the root stage; the value lives in the frame layer,
        # and USD anchors relative asset paths to the layer that holds them.
        if target.is_absolute():
            asset_path = target.as_posix()
        else:
            rel = Path(os.path.relpath(root_dir / target, layer_dir)).as_posix()
            asset_path = rel if rel.startswith("../") else f"./{rel}"
        asset = UsdVol.OpenVDBAsset.Define(stage, f"{path}/{name}")
        asset.CreateFilePathAttr().Set(Sdf.AssetPath(asset_path), time)
        asset.CreateFieldNameAttr(name)
        field_class, data_type, role = _FIELD_KINDS.get(name, (None, None, None))
        if field_class:
            asset.CreateFieldClassAttr(field_class)
            asset.CreateFieldDataTypeAttr(data_type)
        if role:
            asset.CreateVectorDataRoleHintAttr(role)
        volume.CreateFieldRelationship(name, asset.GetPath())


def _write_collider(stage: Any, sample: ColliderSample, time: float) -> None:
    from pxr import Gf, UsdGeom, Vt  # backend: pxr

    _check_name(sample.name, "collider")
    where = f"collider {sample.name!r}"
    pts = _array(sample.points, f"{where}.points", shape=(None, 3), dtype=np.float32)
    tris = _array(sample.faces, f"{where}.faces", shape=(None, 3), dtype=np.int32)
    xform = _array(sample.xform, f"{where}.xform", shape=(4, 4), dtype=np.float64)
    mesh = UsdGeom.Mesh.Define(stage, f"/World/colliders/{sample.name}")
    # Static geometry goes in as defaults: the stitched topology layer keeps one copy of it.
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    # (a deforming one's points and extent are time samples; the attributes in this order either way)
    if sample.animated:
        mesh.CreatePointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts), time)
    else:
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(tris), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(tris.reshape(-1)))
    if sample.animated:
        mesh.CreateExtentAttr().Set(_extent(pts), time)
    else:
        mesh.CreateExtentAttr(_extent(pts))
    op = mesh.MakeMatrixXform()
    # USD multiplies row vectors (translation in the last row): transpose ours.
    op.Set(Gf.Matrix4d(xform.T.tolist()), time)


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


def _write_camera(stage: Any, camera: dict, meters_per_unit: float) -> None:
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


class UsdShotWriter:
    """Writes a shot as per-frame USD layers plus a root stage that stitches them (value clips).

    root_path: the root stage, e.g. export/shot.usda; frames go to frames/NNNN.usdc beside it.
    fps: frames per second (timeCodesPerSecond = framesPerSecond = fps; time code = frame).
    start_frame, end_frame: the shot's frame range (the stage's start/end time codes).
    up_axis: "Y" or "Z"; meters_per_unit: the stage unit in metres. Arrays always arrive in
    metres, Y up; a non-default axis or unit becomes one transform on /World, so raw attribute
    values stay in metres and the composed world positions are in the stage's axis and unit.
    """

    def __init__(
        self,
        root_path: str | Path,
        *,
        fps: float,
        start_frame: int,
        end_frame: int,
        up_axis: str = "Y",
        meters_per_unit: float = 1.0,
    ) -> None:
        self.root_path = Path(root_path)
        if self.root_path.suffix not in (".usda", ".usd", ".usdc"):
            raise ValueError(f"{self.root_path}: the root stage must end in .usda, .usd or .usdc")
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"{self.root_path}: fps {fps!r} must be positive")
        if end_frame < start_frame:
            raise ValueError(f"{self.root_path}: end_frame {end_frame} is before start_frame {start_frame}")
        if up_axis not in ("Y", "Z"):
            raise ValueError(f"{self.root_path}: up_axis {up_axis!r} must be 'Y' or 'Z'")
        if not (math.isfinite(meters_per_unit) and meters_per_unit > 0):
            raise ValueError(f"{self.root_path}: meters_per_unit {meters_per_unit!r} must be positive")
        self.fps, self.start_frame, self.end_frame = float(fps), int(start_frame), int(end_frame)
        self.up_axis, self.meters_per_unit = up_axis, float(meters_per_unit)
        self.frames_dir = self.root_path.parent / "frames"

    def frame_path(self, frame: int) -> Path:
        """Path of the layer holding `frame`: frames/NNNN.usdc beside the root stage."""
        return self.frames_dir / f"{int(frame):04d}.usdc"

    def topology_path(self) -> Path:
        return self.root_path.with_name(f"{self.root_path.stem}.topology.usdc")

    def manifest_path(self) -> Path:
        return self.root_path.with_name(f"{self.root_path.stem}.manifest.usda")

    def _new_stage(self) -> Any:
        from pxr import Usd, UsdGeom  # backend: pxr

        stage = Usd.Stage.CreateInMemory()
        stage.SetTimeCodesPerSecond(self.fps)
        stage.SetFramesPerSecond(self.fps)
        UsdGeom.Xform.Define(stage, "/World")
        stage.SetDefaultPrim(stage.GetPrimAtPath("/World"))
        return stage

    def write_frame(
        self,
        frame: int,
        *,
        points: dict[str, PointsSample] | None = None,
        meshes: dict[str, MeshSample] | None = None,
        volumes: dict[str, dict[str, str]] | None = None,
        colliders: Sequence[ColliderSample] = (),
    ) -> Path:
        """Write frame `frame` to frames/NNNN.usdc (complete or absent) and return its path.

        points / meshes: object name -> sample; volumes: object name -> {field name
        ("surface", "vel", "density"; also the grid name in the file): .vdb path relative to
        the root stage's folder (or absolute)}. Values are time samples at time code `frame`.
        """
        import_pxr()
        from pxr import UsdGeom  # backend: pxr

        stage = self._new_stage()
        time = float(frame)
        groups = {**dict.fromkeys(points or {}), **dict.fromkeys(meshes or {}), **dict.fromkeys(volumes or {})}
        for name in groups:
            _check_name(name, "object")
            UsdGeom.Xform.Define(stage, f"/World/{name}")
        for name, sample in (points or {}).items():
            _write_points(stage, f"/World/{name}/particles", sample, time, f"frame {frame} points[{name!r}]")
        for name, sample in (meshes or {}).items():
            _write_mesh(stage, f"/World/{name}/mesh", sample, time, f"frame {frame} meshes[{name!r}]")
        for name, fields in (volumes or {}).items():
            _write_volume(
                stage,
                f"/World/{name}/volume",
                fields,
                time,
                root_dir=self.root_path.parent,
                layer_dir=self.frames_dir,
                where=f"frame {frame} volumes[{name!r}]",
            )
        if colliders:
            UsdGeom.Scope.Define(stage, "/World/colliders")
        for sample in colliders:
            _write_collider(stage, sample, time)
        path = self.frame_path(frame)
        _export_layer(stage.GetRootLayer(), path)
        return path

    def finalize(self, frames: Sequence[int], *, camera: dict | None = None) -> Path:
        """Stitch the layers of `frames` into the root stage and return its path.

        Writes the topology and manifest layers, then the root last, each atomically, so a
        root on disk always points at complete files. camera: {position, look_at (metres),
        up, focal_length, horizontal_aperture, vertical_aperture (mm), near, far,
        focus_distance (metres), f_stop}; position and look_at are required.
        """
        import_pxr()
        from pxr import Sdf, UsdUtils  # backend: pxr

        frames = sorted({int(f) for f in frames})
        if not frames:
            raise ValueError(f"{self.root_path}: no frames to stitch; write frames first")
        outside = [f for f in frames if not self.start_frame <= f <= self.end_frame]
        if outside:
            raise ValueError(
                f"{self.root_path}: frames {outside[:5]} lie outside the shot range "
                f"[{self.start_frame}, {self.end_frame}]"
            )
        files = [self.frame_path(f) for f in frames]
        missing = [str(p) for p in files if not p.is_file()]
        if missing:
            raise ValueError(
                f"{self.root_path}: frame layers missing: {missing[:5]}; run the export for those frames again"
            )
        clip_files = [str(p) for p in files]
        # The stitching functions save the layers they fill, so they get real (temp) files.
        with _atomic_target(self.topology_path()) as tmp_topology:
            topology = Sdf.Layer.CreateNew(str(tmp_topology))
            UsdUtils.StitchClipsTopology(topology, clip_files)
            with _atomic_target(self.manifest_path()) as tmp_manifest:
                manifest = Sdf.Layer.CreateNew(str(tmp_manifest))
                UsdUtils.StitchClipsManifest(manifest, topology, clip_files, Sdf.Path("/World"))
                manifest.Save()
                del manifest
            topology.Save()
            del topology
        root = self._root_layer(frames, camera)
        _export_layer(root, self.root_path)
        return self.root_path

    def _root_layer(self, frames: list[int], camera: dict | None) -> Any:
        """The root layer: stage metadata, clip metadata on /World, camera; topology sublayered."""
        from pxr import Gf, Sdf, Usd, UsdGeom  # backend: pxr

        layer = Sdf.Layer.CreateAnonymous(".usda")
        stage = Usd.Stage.Open(layer)
        stage.SetTimeCodesPerSecond(self.fps)
        stage.SetFramesPerSecond(self.fps)
        stage.SetStartTimeCode(self.start_frame)
        stage.SetEndTimeCode(self.end_frame)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if self.up_axis == "Y" else UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, self.meters_per_unit)
        world = UsdGeom.Xform.Define(stage, "/World")
        stage.SetDefaultPrim(world.GetPrim())
        clips = Usd.ClipsAPI(world.GetPrim())
        clips.SetClipPrimPath("/World")
        clips.SetClipAssetPaths(
            [f"./{p.relative_to(self.root_path.parent).as_posix()}" for p in map(self.frame_path, frames)]
        )
        clips.SetClipManifestAssetPath(f"./{self.manifest_path().name}")
        clips.SetClipActive([Gf.Vec2d(f, i) for i, f in enumerate(frames)])
        clips.SetClipTimes([Gf.Vec2d(f, f) for f in frames])
        # Arrays are metres, Y up: convert once at the root, not in every frame.
        if self.up_axis == "Z":
            world.AddRotateXOp().Set(90.0)
        if self.meters_per_unit != 1.0:
            world.AddScaleOp().Set(Gf.Vec3f(1.0 / self.meters_per_unit))
        if camera is not None:
            _write_camera(stage, camera, self.meters_per_unit)
        # Add the sublayer without a stage composing it: relative to an in-memory layer it
        # would not resolve (a spurious warning); beside the written root it does.
        del stage
        layer.subLayerPaths.append(f"./{self.topology_path().name}")
        return layer


def validate_stage(path: str | Path, *, include_warnings: bool = False) -> list[str]:
    """Run the registered pxr.UsdValidation validators on the stage at `path`, as `usdchecker
    --useNewValidationFramework` does (all but the usdz-package ones); return the messages of
    errors (and warnings if asked). Empty means clean."""
    import_pxr()
    from pxr import Usd  # backend: pxr

    try:
        from pxr import UsdValidation  # backend: pxr
    except ImportError as exc:
        raise ImportError(f"{INSTALL_HINT} (usd-core >= 25.5 has pxr.UsdValidation)") from exc
    stage = Usd.Stage.Open(str(path))
    if stage is None:
        return [f"{path}: USD could not open the stage"]
    registry = UsdValidation.ValidationRegistry()
    metadata = [m for m in registry.GetAllValidatorMetadata() if "UsdzValidators" not in m.GetKeywords()]
    errors = UsdValidation.ValidationContext(metadata=metadata).Validate(stage)
    kinds = {UsdValidation.ValidationErrorType.Error}
    if include_warnings:
        kinds.add(UsdValidation.ValidationErrorType.Warn)
    return [e.GetErrorAsString() for e in errors if e.GetType() in kinds]
