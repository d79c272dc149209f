"""Animated meshes (deforming or moving) of an asset, sampled at the shot's frames, for colliders.

    load_animation(path, frames, fps) -> Animation(points (F, V, 3) m, faces (T, 3))

USD: every drawn mesh under `prim_path` (as `mpmfx.geometry.usd_asset.load_usd` takes them:
world transforms, metersPerUnit, a Z-up stage stood up) at each frame's time code, so
time-sampled `points` (a skinned and baked character) and time-sampled transforms both move
it. Shot frame f is USD time code f * timeCodesPerSecond / fps (frame numbers, where the file's
rate is the shot's).
.blend / .fbx: Blender evaluates the scene at each frame in its own process
(`mpmfx.geometry.blender_export --frames`): armatures, shape keys, modifiers and object
animation as Cycles renders them; shot frame f is Blender frame f * scene fps / shot fps.

The animation must cover the shot: a USD's time samples (of every attribute under the prim
and its ancestors) must span the first to the last frame's time code, a Blender scene's
frame range the first to the last frame; the topology (the triangles) must be the same at
every frame. Otherwise MeshError, naming the file and what to change.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mpmfx.blender import ERROR, ChildTimeout, bpy_available, child_command, run_child
from mpmfx.geometry.common import MeshError
from mpmfx.geometry.mesh import BLENDER_SUFFIXES, USD_SUFFIXES
from mpmfx.geometry.usd_asset import load_usd

__all__ = ["Animation", "load_animation", "ANIMATED_SUFFIXES"]

ANIMATED_SUFFIXES = USD_SUFFIXES + tuple(s for s in BLENDER_SUFFIXES if s in (".blend", ".fbx"))


@dataclass(frozen=True)
class Animation:
    """points: (F, V, 3) float64 metres in our Y-up world, one row a frame; faces: (T, 3) int64,
    the same at every frame."""

    points: np.ndarray
    faces: np.ndarray


def load_animation(path: Path, frames, fps: float, *, prim_path: str | None = None) -> Animation:
    """The asset at `path` sampled at the shot frames `frames` (frame numbers) of `fps`."""
    path = Path(path)
    frames = [float(f) for f in frames]
    suffix = path.suffix.lower()
    if suffix in USD_SUFFIXES:
        return _usd_animation(path, frames, fps, prim_path)
    if suffix in (".blend", ".fbx"):
        return _blender_animation(path, frames, fps, prim_path)
    raise MeshError(
        f"{path}: an animated collider is read from USD, .blend or .fbx, not '{suffix}': export the "
        "animation as USD (time-sampled points or transforms)"
    )


def _stack(path: Path, frames, samples) -> Animation:
    """samples: (vertices, faces) per frame -> Animation; MeshError where the topology changes."""
    v0, f0 = samples[0]
    for f, (v, faces) in zip(frames, samples):
        if faces.shape != f0.shape or not np.array_equal(faces, f0) or v.shape != v0.shape:
            raise MeshError(
                f"{path}: the mesh's topology changes at frame {f:g} ({len(faces)} triangles, {len(v)} "
                f"vertices; {len(f0)} and {len(v0)} at frame {frames[0]:g}): an animated collider needs the "
                "same faces at every frame; bake it to a fixed-topology mesh"
            )
    return Animation(points=np.stack([v for v, _ in samples]), faces=np.asarray(f0, np.int64))


def _usd_animation(path: Path, frames, fps: float, prim_path: str | None) -> Animation:
    from pxr import Usd  # backend: pxr

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise MeshError(f"{path}: cannot be opened as a USD stage")
    root = stage.GetPrimAtPath(prim_path) if prim_path else stage.GetPseudoRoot()
    if not root or not root.IsValid():
        raise MeshError(f"{path}: prim '{prim_path}' not found; pass an existing prim path or none")
    rate = stage.GetTimeCodesPerSecond() / fps
    codes = [f * rate for f in frames]
    lo, hi = _usd_sample_range(root)
    if lo is None:
        raise MeshError(
            f"{path}: no time samples under '{prim_path or '/'}' (nothing moves): export the "
            "animation (time-sampled points or transforms), or drop animated = true"
        )
    if lo > codes[0] + 1e-6 or hi < codes[-1] - 1e-6:
        raise MeshError(
            f"{path}: the animation's time samples cover time codes {lo:g}..{hi:g}, but the shot "
            f"runs frames {frames[0]:g}..{frames[-1]:g} (time codes {codes[0]:g}..{codes[-1]:g} at "
            f"{stage.GetTimeCodesPerSecond():g} codes/s and {fps:g} fps): export the animation over "
            "the shot's frames or change shot.frame_start / frame_end"
        )
    return _stack(path, frames, [load_usd(path, prim_path, c) for c in codes])


def _usd_sample_range(root) -> tuple[float | None, float | None]:
    """(first, last) time sample of any attribute under `root` or on its ancestors (their
    transforms move it too); (None, None) where nothing is time-sampled."""
    from pxr import Usd  # backend: pxr

    prims = list(Usd.PrimRange(root, Usd.TraverseInstanceProxies()))
    p = root.GetParent()
    while p:
        prims.append(p)
        p = p.GetParent()
    times = [t for prim in prims for attr in prim.GetAttributes() for t in attr.GetTimeSamples()]
    return (min(times), max(times)) if times else (None, None)


def _blender_animation(path: Path, frames, fps: float, part: str | None) -> Animation:
    if not bpy_available():
        raise MeshError(
            f"{path}: reading {path.suffix} animation needs Blender as a Python module (bpy 4.5): "
            "run `bash setup.sh`, or export the animation as USD"
        )
    with tempfile.TemporaryDirectory(prefix="mpmfx-blender-") as tmp:
        out = Path(tmp) / "anim.npz"
        frame_arg = "--frames=" + ",".join(f"{f:g}" for f in frames) + f"@{fps:g}"
        cmd = child_command("mpmfx.geometry.blender_export", str(path.resolve()), str(out), frame_arg)
        try:
            res = run_child(cmd + ([part.lstrip("/")] if part else []), what=str(path))
        except ChildTimeout as exc:
            raise MeshError(str(exc)) from None
        if res.returncode != 0 or not out.is_file():
            lines = (res.stdout + res.stderr).strip().splitlines()
            why = next((s.removeprefix(ERROR) for s in lines if s.startswith(ERROR)), " / ".join(lines[-3:]))
            raise MeshError(f"{path}: {why}")
        with np.load(out) as data:
            counts = data["counts"]
            verts = np.split(data["vertices"], np.cumsum(counts[:, 0])[:-1])
            faces = np.split(data["faces"], np.cumsum(counts[:, 1])[:-1])
    return _stack(path, frames, list(zip(verts, faces)))
