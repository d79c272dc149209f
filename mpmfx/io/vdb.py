"""OpenVDB export: dense numpy blocks (`VdbGrid`) or 8^3 leaves (`LeafGrid`) in world units ->
sparse `.vdb` grids, written atomically.

Index/world convention (OpenVDB's, cell-centred): voxel (i, j, k) holds the value sampled at
world position (i, j, k) * voxel_size metres, so `values[0, 0, 0]` sits at `ijk0 * voxel_size`.
A DCC that loads the file places it correctly with no extra transform.

pyopenvdb (Debian's python3-openvdb 10) is imported only inside the functions that need it.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mpmfx.cache import atomic_path

INSTALL_HINT = (
    "pyopenvdb is not importable: run `bash setup.sh` (it installs Debian's "
    "python3-openvdb and links it into the venv), or as root "
    "`apt-get install python3-openvdb`"
)


class GridClass(str, enum.Enum):
    """What a grid's values mean; mirrors OpenVDB's GridClass (STAGGERED is not used here)."""

    LEVEL_SET = "level_set"  # signed distance in metres, negative inside
    FOG_VOLUME = "fog_volume"  # density in [0, 1], 0 outside
    UNKNOWN = "unknown"  # anything else, e.g. velocity


@dataclass
class VdbGrid:
    """One grid to write.

    name: grid name inside the file ("surface", "vel", "density"); USD fields refer to it.
    values: (a, b, c) float32 scalars or (a, b, c, 3) float32 vectors, world units
        (level set: metres; vel: metres/second).
    ijk0: voxel index of values[0, 0, 0]; world position = index * voxel_size.
    voxel_size: edge length of a voxel, metres.
    grid_class: GridClass or its value string.
    background: value of inactive voxels. For level sets the narrow-band half width in metres
        (> 0): values with |phi| >= background are pruned to +-background.
    half: store the values as 16-bit floats on disk (OpenVDB's saveFloatAsHalf; readers get
        float32 back, ~5e-4 relative): a quarter to a third less disk for render data.
    """

    name: str
    values: np.ndarray
    ijk0: tuple[int, int, int]
    voxel_size: float
    grid_class: GridClass | str = GridClass.LEVEL_SET
    background: float = 0.0
    half: bool = False

    def __post_init__(self) -> None:
        try:
            self.grid_class = GridClass(self.grid_class)
        except ValueError:
            allowed = ", ".join(c.value for c in GridClass)
            raise ValueError(f"VdbGrid {self.name!r}: grid_class {self.grid_class!r} is not one of {allowed}") from None


@dataclass
class LeafGrid:
    """One grid to write, given as OpenVDB-style leaves (what the surface stage stores): no dense
    array over the bounding box, whose size grows with the cube of the shot's resolution.

    name, voxel_size, grid_class, background, half: as VdbGrid.
    block_ijk: (b, 3) int64 voxel index of each leaf's first voxel (multiples of 8).
    blocks: (b, 8, 8, 8) scalars or (b, 8, 8, 8, 3) vectors, float16 or float32, world units.
    inside_ijk: (k, 3) int64 first voxels of leaves wholly set to `inside` (active), or None.
        Level sets need none: signedFloodFill signs whatever the band encloses.
    Voxels outside the leaves hold the background (inactive), as in a VdbGrid's dense block.
    """

    name: str
    block_ijk: np.ndarray
    blocks: np.ndarray
    voxel_size: float
    grid_class: GridClass | str = GridClass.LEVEL_SET
    background: float = 0.0
    half: bool = False
    inside_ijk: np.ndarray | None = None
    inside: float = 1.0

    def __post_init__(self) -> None:
        VdbGrid.__post_init__(self)  # type: ignore[arg-type]


TILE = 4  # leaves along a side of the dense tiles handed to copyFromArray: 32^3 voxels, where its
# per-call cost (~30 us) and its per-voxel cost (~130 Mvoxel/s) balance on one core


def import_pyopenvdb() -> Any:
    """Return the pyopenvdb module, or raise ImportError saying how to install it."""
    try:
        import pyopenvdb  # optional: pyopenvdb
    except ImportError as exc:
        raise ImportError(INSTALL_HINT) from exc
    return pyopenvdb


def _check_grid(grid: VdbGrid, path: Path) -> np.ndarray:
    """Validate one grid; return its values as C-contiguous float32."""
    where = f"{path}: grid {grid.name!r}"
    if not grid.name or not isinstance(grid.name, str):
        raise ValueError(f"{path}: every grid needs a non-empty name")
    values = np.ascontiguousarray(grid.values, dtype=np.float32)
    is_vector = values.ndim == 4 and values.shape[3] == 3
    if values.ndim != 3 and not is_vector:
        raise ValueError(f"{where}: values shape {values.shape}; expected (a, b, c) scalars or (a, b, c, 3) vectors")
    if not np.isfinite(values).all():
        raise ValueError(
            f"{where}: values contain NaN or inf; fix the upstream field (e.g. clamp the level set) before export"
        )
    if len(grid.ijk0) != 3:
        raise ValueError(f"{where}: ijk0 {grid.ijk0!r} must be three integers")
    if not (math.isfinite(grid.voxel_size) and grid.voxel_size > 0):
        raise ValueError(f"{where}: voxel_size {grid.voxel_size!r} must be a positive length in metres")
    if grid.grid_class is GridClass.LEVEL_SET:
        if is_vector:
            raise ValueError(f"{where}: a level set must be scalar; use grid_class='unknown' for vectors")
        if not grid.background > 0:
            raise ValueError(
                f"{where}: a level set needs background = narrow-band half width in "
                f"metres (> 0), got {grid.background!r}; 3 * voxel_size is usual"
            )
    return values


def _check_leaves(grid: LeafGrid, path: Path) -> np.ndarray:
    """Validate one leaf grid; return its blocks, float16 or float32 as given (each tile is cast
    to float32 as it is filled: a 10M-face frame's velocity leaves are 270M half floats, a
    second's pass and 1 GB as float32), a level set's clamped to the band."""
    where = f"{path}: grid {grid.name!r}"
    if not grid.name or not isinstance(grid.name, str):
        raise ValueError(f"{path}: every grid needs a non-empty name")
    blocks = np.asarray(grid.blocks)
    if blocks.dtype not in (np.float16, np.float32):
        blocks = blocks.astype(np.float32)
    ijk = np.asarray(grid.block_ijk)
    if blocks.shape[1:4] != (8, 8, 8) or blocks.ndim not in (4, 5) or blocks.shape[4:] not in ((), (3,)):
        raise ValueError(f"{where}: blocks shape {blocks.shape}; expected (b, 8, 8, 8) or (b, 8, 8, 8, 3)")
    if ijk.shape != (len(blocks), 3) or np.any(ijk % 8):
        raise ValueError(f"{where}: block_ijk shape {ijk.shape}; expected ({len(blocks)}, 3) multiples of 8")
    if not _finite(blocks):
        raise ValueError(
            f"{where}: values contain NaN or inf; fix the upstream field (e.g. clamp the level set) before export"
        )
    if not (math.isfinite(grid.voxel_size) and grid.voxel_size > 0):
        raise ValueError(f"{where}: voxel_size {grid.voxel_size!r} must be a positive length in metres")
    if grid.grid_class is GridClass.LEVEL_SET:
        if blocks.ndim == 5:
            raise ValueError(f"{where}: a level set must be scalar; use grid_class='unknown' for vectors")
        if not grid.background > 0:
            raise ValueError(f"{where}: a level set needs background = narrow-band half width in metres (> 0)")
        band = blocks.dtype.type(grid.background)  # as _level_set_grid: outside the band is +band, then flood-filled
        blocks = np.where(np.abs(blocks) < band, blocks, band)
    return blocks


def _finite(a: np.ndarray) -> bool:
    """No NaN or inf in `a` (float16: an all-ones exponent, tested on the bits ~10x faster)."""
    if a.dtype == np.float16:
        return not np.any((a.view(np.uint16) & 0x7C00) == 0x7C00)
    return bool(np.isfinite(a).all())


def _copy_leaves(out: Any, ijk: np.ndarray, blocks: np.ndarray, background, tolerance) -> None:
    """copyFromArray the leaves into `out`, TILE^3 leaves at a time (background between them)."""
    if not len(blocks):
        return
    side, tail = 8 * TILE, blocks.shape[4:]
    leaf = np.asarray(ijk, np.int64) // 8
    tile = leaf // TILE
    order = np.lexsort(tile.T[::-1])
    leaf, tile, blocks = leaf[order], tile[order], blocks[order]
    starts = np.flatnonzero(np.r_[True, np.any(tile[1:] != tile[:-1], axis=1), True])
    dense = np.empty((side, side, side, *tail), np.float32)
    # the tile seen as (tile x, tile y, tile z, 8, 8, 8, ...): one leaf a fancy index
    view = dense.reshape(TILE, 8, TILE, 8, TILE, 8, *tail).transpose(0, 2, 4, 1, 3, 5, *range(6, 6 + len(tail)))
    for a, b in zip(starts[:-1], starts[1:]):
        dense.fill(background)
        local = leaf[a:b] - tile[a] * TILE
        view[local[:, 0], local[:, 1], local[:, 2]] = blocks[a:b]
        out.copyFromArray(dense, ijk=tuple(int(i) for i in tile[a] * side), tolerance=tolerance)


def _fill_leaves(out: Any, ijk: np.ndarray, value) -> None:
    """Set the leaves at `ijk` (first voxels) to `value`, active: one fill per run along z."""
    if ijk is None or not len(ijk):
        return
    leaf = np.unique(np.asarray(ijk, np.int64) // 8, axis=0)  # sorted x, y, z
    breaks = np.flatnonzero(np.r_[True, np.any(leaf[1:, :2] != leaf[:-1, :2], axis=1) | (np.diff(leaf[:, 2]) != 1)])
    for a, b in zip(breaks, np.r_[breaks[1:], len(leaf)]):
        lo = leaf[a] * 8
        hi = leaf[b - 1] * 8 + 7
        out.fill(tuple(int(i) for i in lo), tuple(int(i) for i in hi), value, True)


def _not_stored(grid: LeafGrid) -> np.ndarray | None:
    """The inside leaves that are not stored leaves too (a stored leaf's values win). They are
    filled after the tiles are copied: a tile's copy sets every voxel of its box."""
    if grid.inside_ijk is None or not len(grid.inside_ijk) or not len(grid.block_ijk):
        return grid.inside_ijk
    inside, stored = np.asarray(grid.inside_ijk, np.int64), np.asarray(grid.block_ijk, np.int64)
    key = lambda a: (a[:, 0] * (1 << 21) + a[:, 1]) * (1 << 21) + a[:, 2]  # noqa: E731 (leaf-unit ijk < 2^20)
    return inside[~np.isin(key(inside // 8), key(stored // 8))]


def _build_leaf_grid(vdb: Any, grid: LeafGrid, blocks: np.ndarray) -> Any:
    """The same grid `_build_grid` makes from the leaves pasted into a dense block."""
    if blocks.ndim == 5:
        zero = (float(grid.background),) * 3
        out = vdb.Vec3SGrid(zero)
        out.vectorType = vdb.VectorType.CONTRAVARIANT_RELATIVE
        _copy_leaves(out, grid.block_ijk, blocks, grid.background, (0.0, 0.0, 0.0))
        _fill_leaves(out, _not_stored(grid), (float(grid.inside),) * 3)
        out.prune((0.0, 0.0, 0.0))
    else:
        out = vdb.FloatGrid(float(grid.background))
        _copy_leaves(out, grid.block_ijk, blocks, grid.background, 0)
        if grid.grid_class is not GridClass.LEVEL_SET:
            _fill_leaves(out, _not_stored(grid), float(grid.inside))
        if grid.grid_class is GridClass.LEVEL_SET:
            out.gridClass = vdb.GridClass.LEVEL_SET
            out.signedFloodFill()
        out.prune()
    if grid.grid_class is GridClass.FOG_VOLUME:
        out.gridClass = vdb.GridClass.FOG_VOLUME
    out.name = grid.name
    out.saveFloatAsHalf = bool(grid.half)
    out.transform = vdb.createLinearTransform(float(grid.voxel_size))
    return out


def _level_set_grid(vdb: Any, grid: VdbGrid, values: np.ndarray) -> Any:
    """Narrow-band level set: only |phi| < band is active, the rest are +-band tiles."""
    band = np.float32(grid.background)
    # Everything outside the band is written as +band (inactive, equal to the background);
    # signedFloodFill then flips the inactive voxels and tiles inside the surface to -band.
    banded = np.where(np.abs(values) < band, values, band).astype(np.float32, copy=False)
    out = vdb.FloatGrid(float(band))
    out.gridClass = vdb.GridClass.LEVEL_SET
    out.copyFromArray(banded, ijk=tuple(int(i) for i in grid.ijk0), tolerance=0)
    out.signedFloodFill()
    out.prune()
    return out


def _build_grid(vdb: Any, grid: VdbGrid, values: np.ndarray) -> Any:
    ijk = tuple(int(i) for i in grid.ijk0)
    if grid.grid_class is GridClass.LEVEL_SET:
        out = _level_set_grid(vdb, grid, values)
    elif values.ndim == 4:
        out = vdb.Vec3SGrid((float(grid.background),) * 3)
        # Velocities are displacements per time: rotate/scale with the transform, no translation.
        out.vectorType = vdb.VectorType.CONTRAVARIANT_RELATIVE
        out.copyFromArray(values, ijk=ijk, tolerance=(0.0, 0.0, 0.0))
        out.prune((0.0, 0.0, 0.0))
    else:
        out = vdb.FloatGrid(float(grid.background))
        out.copyFromArray(values, ijk=ijk, tolerance=0)
        out.prune()
    if grid.grid_class is GridClass.FOG_VOLUME:
        out.gridClass = vdb.GridClass.FOG_VOLUME
    out.name = grid.name
    out.saveFloatAsHalf = bool(grid.half)
    out.transform = vdb.createLinearTransform(float(grid.voxel_size))
    return out


def _check_metadata(metadata: dict[str, Any], path: Path) -> dict[str, Any]:
    clean: dict[str, Any] = {}
    for key, value in metadata.items():
        if not isinstance(key, str) or not key:
            raise ValueError(f"{path}: metadata key {key!r} must be a non-empty string")
        if isinstance(value, (bool, np.bool_)):
            clean[key] = bool(value)
        elif isinstance(value, (int, np.integer)):
            clean[key] = int(value)
        elif isinstance(value, (float, np.floating)):
            clean[key] = float(value)
        elif isinstance(value, str):
            clean[key] = value
        else:
            raise ValueError(
                f"{path}: metadata {key!r} has type {type(value).__name__}; use str, int or float (e.g. json.dumps it)"
            )
    return clean


def write_vdb(path: str | Path, grids: Sequence[VdbGrid | LeafGrid], *, metadata: dict[str, str | int | float]) -> Path:
    """Write `grids` and file-level `metadata` to `path` (.vdb) so that the file is complete or absent.

    Level sets get class LEVEL_SET and background = band (metres); fog volumes class FOG_VOLUME;
    vector grids vectorType "contravariant relative" (velocity). Voxels equal to the background
    are stored inactive, so a field that is mostly empty costs little.
    Returns the path written.
    """
    path = Path(path)
    if path.suffix != ".vdb":
        raise ValueError(f"{path}: OpenVDB files must end in .vdb")
    if not grids:
        raise ValueError(f"{path}: no grids to write")
    names = [g.name for g in grids]
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: grid names {names} repeat; each grid needs its own name")
    checked = [(g, _check_leaves(g, path) if isinstance(g, LeafGrid) else _check_grid(g, path)) for g in grids]
    file_metadata = _check_metadata(metadata, path)
    vdb = import_pyopenvdb()
    vdb_grids = [
        _build_leaf_grid(vdb, g, values) if isinstance(g, LeafGrid) else _build_grid(vdb, g, values)
        for g, values in checked
    ]

    def readable(tmp: Path) -> bool:  # pyopenvdb reports no error when a write fails: read it back
        return sorted(g.name for g in vdb.readAllGridMetadata(str(tmp))) == sorted(names)

    with atomic_path(path, verify=readable, checksum=True) as tmp:
        vdb.write(str(tmp), grids=vdb_grids, metadata=file_metadata)
    return path


# pyopenvdb reports classes by their OpenVDB names.
_CLASS_FROM_VDB = {"level set": GridClass.LEVEL_SET, "fog volume": GridClass.FOG_VOLUME, "unknown": GridClass.UNKNOWN}


def _grid_info(vdb: Any, grid: Any, *, with_values: bool) -> dict[str, Any]:
    vector = isinstance(grid, vdb.Vec3SGrid)
    info: dict[str, Any] = {
        "class": _CLASS_FROM_VDB.get(str(grid.gridClass), str(grid.gridClass)),
        "value_type": grid.valueTypeName,
        "voxel_size": tuple(float(v) for v in grid.transform.voxelSize()),
        "active_voxel_count": int(grid.activeVoxelCount()),
        "background": grid.background,
        "vector_type": str(grid.vectorType) if vector else None,
        "metadata": dict(grid.metadata),
    }
    if with_values:
        lo, hi = grid.evalActiveVoxelBoundingBox()
        shape = tuple(max(int(h) - int(l) + 1, 0) for l, h in zip(lo, hi))
        dense = np.zeros(shape + ((3,) if vector else ()), dtype=np.float32)
        if dense.size:
            grid.copyToArray(dense, ijk=tuple(int(v) for v in lo))
        info["ijk0"] = tuple(int(v) for v in lo)
        info["values"] = dense
    return info


def read_vdb(path: str | Path, *, with_values: bool = False) -> dict[str, Any]:
    """Summarise a .vdb file (for tests and tools).

    Returns {"metadata": file metadata dict, "grids": {name: info}} where info has "class"
    (GridClass), "value_type", "voxel_size" (dx, dy, dz) metres, "active_voxel_count",
    "background", "vector_type" (vector grids, else None) and the grid's "metadata". With
    with_values=True each info also has "ijk0" and "values": the dense block over the active
    bounding box (inactive voxels hold the background, level-set interiors -background).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such .vdb file")
    vdb = import_pyopenvdb()
    grids, metadata = vdb.readAll(str(path))
    return {"metadata": dict(metadata), "grids": {g.name: _grid_info(vdb, g, with_values=with_values) for g in grids}}
