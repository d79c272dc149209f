"""USD export: one binary crate layer per frame, stitched into a shot stage with value clips.

Layout on disk (all paths relative to the root stage's folder)::

    shot.usda                 root: stage metadata, clip metadata on /World, camera
    shot.topology.usdc        every prim and static property of the frames, no time samples
    shot.manifest.usda        which attributes the clips hold time samples for
    frames/NNNN.usdc          one frame: time samples at time code = frame

Prims (names from the caller, each a valid prim name; world units are metres, Y up, exactly as
the arrays came in)::

    /World                    Xform; carries the unit / up-axis correction if the stage is not m, Y
    /World/surfaces/<name>    UsdGeomMesh (points, triangles, normals, velocities); a bound
                              UsdPreviewSurface material and a displayColor (finalize's looks)
    /World/particles/<name>   UsdGeomPoints (points, velocities, widths, ids, primvars:*); invisible
    /World/volumes/<name>     UsdVolVolume, field:<field> -> /World/volumes/<name>/<name>_<field>
                              (UsdVolOpenVDBAsset, filePath time-sampled per frame); invisible
    /World/colliders/<name>   UsdGeomMesh, static local geometry, animated xformOp:transform
    /World/looks/<look>       UsdShadeMaterial with a UsdPreviewSurface shader (finalize's looks)
    /World/camera             UsdGeomCamera (if finalize is given one)

Particles and level-set volumes are data for the artist, not pictures: a plain import of the
stage shows the surfaces only (the particles would draw spheres through every surface, a level
set fog). Blender's importer skips invisible prims by default; `import_visible_only=False`
brings them in hidden. Every name a DCC makes an object of is distinct (Blender's object names
are one namespace), so the caller gives particles and volumes names of their own.

The root opens without touching any frame file: USD opens a clip only when one of its values
is read, so the cost of opening grows with the clip list (a few bytes a frame), not the data.
pxr (usd-core) is imported only inside the functions that need it.
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from time import perf_counter
from typing import Any

import numpy as np

from mpmfx.cache import atomic_path
from mpmfx.diskspace import ensure_room
from mpmfx.io.usd_view import PreviewLook, bind_look, check_name, write_camera

INSTALL_HINT = (
    "pxr (usd-core) is not importable: run `bash setup.sh`, or "
    "`pip install usd-core` in the environment that runs mpmfx"
)

SCOPES = {"surfaces": "surface", "particles": "points", "volumes": "volume", "colliders": "collider"}
HIDDEN_SCOPES = ("particles", "volumes")  # invisible by default in the root layer
# Known VDB fields: fieldClass, fieldDataType, vectorDataRoleHint (None = not authored).
_FIELD_KINDS = {
    "surface": ("levelSet", "float", None),
    "density": ("fogVolume", "float", None),
    "vel": ("unknown", "float3", "Vector"),
}


def import_pxr() -> Any:
    """Return the pxr package with the modules used here loaded, or raise ImportError saying
    how to install it."""
    try:
        import pxr  # backend: pxr
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, UsdUtils, UsdVol, Vt  # backend: pxr  # noqa: F401
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
    from pxr import Sdf, Tf  # backend: pxr

    ensure_room(path)  # USD on a full disk fails only after a page of its own errors
    readable = lambda tmp: Sdf.Layer.OpenAsAnonymous(str(tmp)) is not None  # noqa: E731
    try:
        with atomic_path(path, verify=readable, checksum=True) as tmp:
            yield tmp
    except Tf.ErrorException as exc:  # not the disk (atomic_path says that): USD's first line only
        raise OSError(errno.EIO, f"USD could not write the layer: {_usd_reason(exc)}", str(path)) from None
    _reload_if_open(path)


def _usd_reason(exc: Exception) -> str:
    """The first of USD's errors, without its C++ function and source line."""
    first = next((line.strip() for line in str(exc).splitlines() if line.strip()), "no reason given")
    said = re.search(r" : '(.*)'$", first)
    return (said.group(1) if said else first)[:200]


def _reload_if_open(path: Path) -> None:
    """A layer this process already opened from `path` would keep serving the old content."""
    from pxr import Sdf  # backend: pxr

    layer = Sdf.Layer.Find(str(path))
    if layer is not None:
        layer.Reload(True)


def _export_layer(layer: Any, path: Path) -> None:
    with _atomic_target(path) as tmp:
        if not layer.Export(str(tmp)):
            raise OSError(errno.EIO, "USD could not write the layer (disk full or no permission?)", str(tmp))


def _array(value: Any, where: str, *, shape: tuple[int | None, ...], dtype: type) -> np.ndarray:
    """Check `value` against `shape` (None = any length) and return it C-contiguous in `dtype`."""
    arr = np.asarray(value)
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{where}: shape {arr.shape}, expected {want}")
    out = np.ascontiguousarray(arr, dtype=dtype)
    # min and max carry a NaN or an inf through, and read the array without a mask the size of it;
    # on the float32 copy: numpy reduces half floats (the surface frames' normals) ~10x slower
    if np.issubdtype(arr.dtype, np.floating) and out.size and not np.isfinite([out.min(), out.max()]).all():
        raise ValueError(f"{where}: contains NaN or inf; the upstream stage produced invalid values")
    return out


def _extent(points: np.ndarray, pad: float = 0.0) -> Any:
    from pxr import Vt  # backend: pxr

    if len(points) == 0:
        return Vt.Vec3fArray.FromNumpy(np.zeros((2, 3), np.float32))
    # a column at a time: numpy's min(axis=0) over (n, 3) runs ~4x slower (220 ms at 5M points)
    lo = [points[:, i].min() - pad for i in range(3)]
    hi = [points[:, i].max() + pad for i in range(3)]
    box = np.array([lo, hi], np.float32)
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
        check_name(name, f"{where} primvar")
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
    mesh.CreateFaceVertexCountsAttr().Set(Vt.IntArray(len(tris), 3), time)  # (filled in C++: 4x numpy's copy)
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
        check_name(name, f"{where} field")
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
        asset = UsdVol.OpenVDBAsset.Define(stage, f"{path}/{path.rsplit('/', 1)[1]}_{name}")
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

    check_name(sample.name, "collider")
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
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray(len(tris), 3))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(tris.reshape(-1)))
    if sample.animated:
        mesh.CreateExtentAttr().Set(_extent(pts), time)
    else:
        mesh.CreateExtentAttr(_extent(pts))
    op = mesh.MakeMatrixXform()
    # USD multiplies row vectors (translation in the last row): transpose ours.
    op.Set(Gf.Matrix4d(xform.T.tolist()), time)


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
        seconds: dict[str, float] | None = None,
    ) -> Path:
        """Write frame `frame` to frames/NNNN.usdc (complete or absent) and return its path.

        points: prim name -> sample (/World/particles/<name>); meshes: prim name -> sample
        (/World/surfaces/<name>); volumes: prim name (/World/volumes/<name>) -> {field name
        ("surface", "vel", "density"; also the grid name in the file): .vdb path relative to
        the root stage's folder (or absolute)}. Values are time samples at time code `frame`.
        seconds: where the time went is added to it, s: "usd" (the layer built in memory) and
        "write" (written, checksummed, read back).
        """
        import_pxr()
        from pxr import UsdGeom  # backend: pxr

        t0 = perf_counter()
        stage = self._new_stage()
        time = float(frame)
        for scope, items in (("particles", points), ("surfaces", meshes), ("volumes", volumes)):
            for name in items or {}:
                check_name(name, SCOPES[scope])
            if items:
                UsdGeom.Scope.Define(stage, f"/World/{scope}")
        for name, sample in (points or {}).items():
            _write_points(stage, f"/World/particles/{name}", sample, time, f"frame {frame} points[{name!r}]")
        for name, sample in (meshes or {}).items():
            _write_mesh(stage, f"/World/surfaces/{name}", sample, time, f"frame {frame} meshes[{name!r}]")
        for name, fields in (volumes or {}).items():
            _write_volume(
                stage,
                f"/World/volumes/{name}",
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
        t1 = perf_counter()
        _export_layer(stage.GetRootLayer(), path)
        if seconds is not None:
            seconds["usd"] = seconds.get("usd", 0.0) + t1 - t0
            seconds["write"] = seconds.get("write", 0.0) + perf_counter() - t1
        return path

    def finalize(
        self, frames: Sequence[int], *, camera: dict | None = None, looks: dict[str, PreviewLook] | None = None
    ) -> Path:
        """Stitch the layers of `frames` into the root stage and return its path. The stage's
        start and end time codes are the first and last of `frames` (what was run).

        Writes the topology and manifest layers, then the root last, each atomically, so a
        root on disk always points at complete files. camera: {position, look_at (metres),
        up, focal_length, horizontal_aperture, vertical_aperture (mm), near, far,
        focus_distance (metres), f_stop}; position and look_at are required.
        looks: surface prim name -> its `PreviewLook`: a UsdPreviewSurface material bound to the
        mesh, and its displayColor.
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
            hidden = [
                f"/World/{scope}/{name}"
                for scope in HIDDEN_SCOPES
                if (spec := topology.GetPrimAtPath(f"/World/{scope}")) is not None
                for name in spec.nameChildren.keys()
            ]
            topology.Save()
            del topology
        root = self._root_layer(frames, camera, looks or {}, hidden)
        _export_layer(root, self.root_path)
        return self.root_path

    def _root_layer(
        self, frames: list[int], camera: dict | None, looks: dict[str, PreviewLook], hidden: list[str]
    ) -> Any:
        """The root layer: stage metadata, clip metadata on /World, camera, materials, what is
        hidden; topology sublayered."""
        from pxr import Gf, Sdf, Usd, UsdGeom  # backend: pxr

        layer = Sdf.Layer.CreateAnonymous(".usda")
        stage = Usd.Stage.Open(layer)
        stage.SetTimeCodesPerSecond(self.fps)
        stage.SetFramesPerSecond(self.fps)
        stage.SetStartTimeCode(frames[0])  # the frames run (e.g. --frames 1:12), not the shot's range
        stage.SetEndTimeCode(frames[-1])
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
            write_camera(stage, camera, self.meters_per_unit)
        for path in hidden:
            UsdGeom.Imageable(stage.OverridePrim(path)).CreateVisibilityAttr(UsdGeom.Tokens.invisible)
        for name, look in looks.items():
            check_name(name, "surface")
            bind_look(stage, f"/World/surfaces/{name}", look)
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
