"""Mesh loading, placement and domain checks.

All lengths are world units (metres). Formats: OBJ, PLY, STL, GLB/glTF through trimesh
(scenes are flattened with their node transforms), Blender and FBX files through Blender in
its own process (mpmfx.geometry.blender_export) and USD/USDA/USDC/USDZ through ``pxr``
(mpmfx.geometry.usd_asset: what a renderer draws, Y-up, in metres).
pxr is imported inside mpmfx.geometry.usd_asset's functions; bpy only in Blender's own process.
"""

from __future__ import annotations

import json
import struct
import tempfile
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from mpmfx.blender import ERROR, ChildTimeout, bpy_available, child_command, run_child
from mpmfx.geometry.common import MeshError
from mpmfx.geometry.usd_asset import load_usd

TRIMESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")  # a compressed glTF goes to Blender
USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
BLENDER_SUFFIXES = (".blend", ".fbx")

# A mesh whose smallest bounding-box side is below this fraction of its largest is flat:
# it has no interior to fill with particles.
_FLAT_RATIO = 1e-6
# A coordinate beyond this, in the file's units, is no asset's: a planet in millimetres is
# 1.3e10, a city block in millimetres 1e6. Such a vertex (an exporter's garbage, an unapplied
# 1e30 "infinity") would otherwise make the mesh read as flat or as larger than any domain.
_ABSURD = 1e9


def load_mesh(path: str | Path, *, prim_path: str | None = None) -> "trimesh.Trimesh":
    """Load a triangle mesh in world units (metres).

    path: OBJ, PLY, STL, GLB/glTF, .blend, .fbx or USD/USDA/USDC/USDZ file.
    prim_path: USD: load the meshes under this prim; .blend / .fbx: the object or collection of
        this name (a leading / ignored); default: the whole file.
    Returns one ``trimesh.Trimesh`` (all parts concatenated, transforms applied,
    n-gons triangulated). Raises ``MeshError`` for a missing, unreadable, empty or
    degenerate (flat, zero-volume) mesh.
    """
    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: no such file; check the asset path (relative paths are relative to {Path.cwd()})")
    suffix = path.suffix.lower()
    if suffix in USD_SUFFIXES:
        vertices, faces = load_usd(path, prim_path)
    elif suffix in BLENDER_SUFFIXES or _compressed_gltf(path):  # Blender decodes Draco and meshopt
        vertices, faces = _load_blender(path, prim_path)
    elif prim_path is not None and suffix in TRIMESH_SUFFIXES:
        raise MeshError(
            f"{path}: prim_path '{prim_path}' names a part of a USD, .blend or .fbx file; a "
            f"{suffix} file is taken whole: drop prim_path or export the part on its own"
        )
    elif suffix in TRIMESH_SUFFIXES:
        vertices, faces = _load_trimesh(path)
    else:
        raise MeshError(
            f"{path}: unsupported format '{suffix}'; export the asset as one of "
            f"{', '.join(TRIMESH_SUFFIXES + BLENDER_SUFFIXES + USD_SUFFIXES)}"
        )
    bad = np.flatnonzero(~np.isfinite(vertices).all(axis=1))
    if len(bad):  # checked before trimesh, which would drop them (and their faces) silently
        raise MeshError(
            f"{path}: {len(bad)} vertices are NaN or inf (the first is vertex {bad[0]}); "
            "clean up the asset in your DCC and re-export it"
        )
    far = np.flatnonzero(np.abs(vertices).max(axis=1, initial=0.0) > _ABSURD)
    if len(far):  # before trimesh too: its vertex merge overflows on them
        raise MeshError(
            f"{path}: {len(far)} vertices lie absurdly far out (vertex {far[0]} at "
            f"{np.array2string(np.asarray(vertices[far[0]]), precision=3)}; no asset's coordinate "
            f"exceeds {_ABSURD:g} in its file's units): a broken export; clean up the asset in your DCC "
            f"and re-export it"
        )
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=True)
    _validate(mesh, path)
    return mesh


GLTF_COMPRESSION = ("KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_meshopt_compression")
"""glTF extensions that compress meshes: trimesh reads such a file as empty geometry, Blender decodes it."""


def _compressed_gltf(path: Path) -> bool:
    """Whether a .glb / .gltf file's meshes are compressed (GLTF_COMPRESSION in its extensions)."""
    suffix = path.suffix.lower()
    if suffix not in (".glb", ".gltf"):
        return False
    try:
        with open(path, "rb") as fh:
            if suffix == ".gltf":
                doc = json.load(fh)
            else:  # 12-byte header, then the JSON chunk: length, type, data
                fh.seek(12)
                length, kind = struct.unpack("<I4s", fh.read(8))
                doc = json.loads(fh.read(length)) if kind == b"JSON" else {}
    except (OSError, ValueError, struct.error):
        return False  # unreadable: trimesh says so, naming the file
    used = set(doc.get("extensionsUsed", [])) | set(doc.get("extensionsRequired", []))
    return bool(used & set(GLTF_COMPRESSION))


def _load_trimesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        scene = trimesh.load_scene(str(path), process=False)  # keep NaN vertices: load_mesh refuses them
        parts = [g for g in scene.dump(concatenate=False) if isinstance(g, trimesh.Trimesh) and len(g.faces)]
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise MeshError(
            f"{path}: cannot be read as a mesh ({type(exc).__name__}: {exc}); re-export it from your DCC"
        ) from exc
    if not parts:
        raise MeshError(
            f"{path}: contains no triangles (only points, lines or an empty "
            "scene); export the surface as a polygon mesh"
        )
    merged = trimesh.util.concatenate(parts)
    return np.asarray(merged.vertices, float), np.asarray(merged.faces, np.int64)


def _load_blender(path: Path, part: str | None) -> tuple[np.ndarray, np.ndarray]:
    """A .blend or .fbx file's rendered surfaces, or those of the object or collection named
    `part`, from Blender in its own process."""
    if not bpy_available():
        raise MeshError(
            f"{path}: reading {path.suffix} files needs Blender as a Python module (bpy 4.5): "
            "run `bash setup.sh`, or export the asset as USD, glTF or OBJ"
        )
    with tempfile.TemporaryDirectory(prefix="mpmfx-blender-") as tmp:
        out = Path(tmp) / "mesh.npz"
        cmd = child_command("mpmfx.geometry.blender_export", str(path.resolve()), str(out))
        try:
            res = run_child(cmd + ([part.lstrip("/")] if part else []), what=str(path))
        except ChildTimeout as exc:
            raise MeshError(str(exc)) from None
        if res.returncode != 0 or not out.is_file():
            lines = (res.stdout + res.stderr).strip().splitlines()
            why = next((s.removeprefix(ERROR) for s in lines if s.startswith(ERROR)), " / ".join(lines[-3:]))
            raise MeshError(
                f"{path}: Blender could not read it ({why}); open it in Blender to check it, "
                "or export the asset as USD, glTF or OBJ"
            )
        with np.load(out) as data:
            return data["vertices"], data["faces"]


def _validate(mesh: "trimesh.Trimesh", path: Path | str) -> None:
    if len(mesh.faces) == 0:
        raise MeshError(f"{path}: no non-degenerate triangles; export the surface as a polygon mesh")
    if not np.all(np.isfinite(mesh.vertices)):
        raise MeshError(f"{path}: vertices contain NaN or inf; clean up the asset in your DCC")
    extents = mesh.extents
    if extents.max() <= 0 or extents.min() <= _FLAT_RATIO * extents.max():
        raise MeshError(
            f"{path}: the mesh is flat (bounding box {np.round(extents, 6)} m); "
            "a simulated solid needs volume: give it thickness (e.g. solidify)"
        )
    if mesh.is_watertight:
        if mesh.volume < 0:  # inverted normals: fix so inside tests see an outward surface
            trimesh.repair.fix_inversion(mesh)
        if abs(mesh.volume) <= _FLAT_RATIO * np.prod(extents):
            raise MeshError(
                f"{path}: the closed mesh has zero volume; a simulated solid "
                "needs an interior (check for collapsed or doubled faces)"
            )


def transform_mesh(
    mesh: "trimesh.Trimesh", *, translate=(0.0, 0.0, 0.0), rotate_deg=(0.0, 0.0, 0.0), scale=1.0
) -> "trimesh.Trimesh":
    """Return a scaled, then rotated, then translated copy of ``mesh``.

    translate: (3,) metres. rotate_deg: (3,) XYZ Euler angles in degrees (about the fixed
    world x, then y, then z axes). scale: scalar or (3,) factor, applied about the origin.
    """
    s = np.broadcast_to(np.asarray(scale, float), (3,))
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise MeshError(f"scale={scale!r}: scale factors must be positive; use rotate_deg to flip an asset")
    rot = Rotation.from_euler("xyz", np.asarray(rotate_deg, float), degrees=True).as_matrix()
    out = mesh.copy()
    out.vertices = (np.asarray(mesh.vertices, float) * s) @ rot.T + np.asarray(translate, float)
    return out


def check_in_domain(mesh: "trimesh.Trimesh", *, origin, size: float, name: str, floor: float | None = None) -> None:
    """Raise ``MeshError`` unless ``mesh`` lies inside the cube [origin, origin + size], and
    above ``floor`` where given.

    origin: (3,) metres, min corner of the domain. size: edge length in metres. floor: world
    height (m) of the solver's floor, the plane of its lowest wall (material below it starts inside
    the wall). name: the asset's name for the message. The message says what to change; a
    translation it advises puts the mesh inside, above the floor.
    """
    lo, hi = np.asarray(mesh.bounds[0], float), np.asarray(mesh.bounds[1], float)
    o = np.asarray(origin, float)
    room_lo, room_hi = o.copy(), o + size
    if floor is not None:
        room_lo[1] = max(room_lo[1], float(floor))
    extent = hi - lo
    if np.any(extent > size):
        factor = size / extent.max()
        raise MeshError(
            f"{name}: mesh is {_fmt(extent)} m, larger than the domain (size {size:g} m); "
            f"scale it by at most {factor:.3g} or set domain.size >= {extent.max():.4g}"
        )
    if extent[1] > room_hi[1] - room_lo[1]:
        raise MeshError(
            f"{name}: mesh is {extent[1]:.4g} m tall, taller than the {room_hi[1] - room_lo[1]:.4g} m from "
            f"the solver's floor (y = {room_lo[1]:.4g} m) to the domain's top; scale it by at most "
            f"{(room_hi[1] - room_lo[1]) / extent[1]:.3g}, or lower domain.origin or raise domain.size"
        )
    slack = 1e-6 * size  # a mesh resting on the floor or a face, up to rounding, is inside
    if np.any(lo < room_lo - slack) or np.any(hi > room_hi + slack):
        if floor is not None and lo[1] < room_lo[1] - slack and np.all(lo >= o) and np.all(hi <= room_hi):
            where = (
                f"starts below the solver's floor: its lowest point is y = {lo[1]:.4g} m, the floor "
                f"y = {room_lo[1]:.4g} m (its plane, 3 cells above domain.origin)"
            )
        else:
            where = f"mesh bounds {_fmt(lo)}..{_fmt(hi)} m extend outside the domain {_fmt(o)}..{_fmt(o + size)} m" + (
                f" above the solver's floor (y = {room_lo[1]:.4g} m)" if floor is not None else ""
            )
        raise MeshError(f"{name}: {where}; translate it by {_shift(lo, hi, room_lo, room_hi)} m or move domain.origin")


def _shift(lo: np.ndarray, hi: np.ndarray, room_lo: np.ndarray, room_hi: np.ndarray) -> str:
    """The smallest translation (m) that puts [lo, hi] inside [room_lo, room_hi], as text with
    as few digits as keep it inside: a rounded shift never leaves the mesh short of the room,
    nor past its other side."""
    out = []
    for a, b in zip(room_lo - lo, room_hi - hi):  # the shifts that fit on this axis: a..b
        want = a if a > 0 else (b if b < 0 else 0.0)
        if want == 0.0:
            out.append("0")
            continue
        text = "0"
        for digits in range(4, 12):
            text = f"{want:.{digits}g}"
            if a - 1e-12 <= float(text) <= b + 1e-12:
                break
        out.append(text)
    return "(" + ", ".join(out) + ")"


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in np.asarray(v, float)) + ")"
