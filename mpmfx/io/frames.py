"""Per-frame array files: a versioned `.npz` of named arrays, written atomically, and the
typed records that stages exchange through them (SeedParticles, ParticleFrame, SurfaceFrame).

Stages read and write each other's outputs only through these records, never through a
sibling stage. The output is byte-for-byte deterministic for the same arrays, which the cache
tests rely on.
"""

from __future__ import annotations

import dataclasses
import zipfile
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mpmfx.cache import atomic_path
from mpmfx.io.npz import read_npz, write_npz

FRAME_FORMAT = 2  # 2: particle ids dropped when they count 0..n-1; surface normals, velocities float16
READS = (1, 2)  # older frames still read: what changed is what a writer leaves out or rounds


def write_arrays(path: str | Path, arrays: dict[str, np.ndarray], *, compress: bool | Collection[str] = False) -> Path:
    """Write `arrays` to `path` (.npz) so that the file is complete or absent.

    compress: True, False, or the names of the arrays worth deflating (a level set is mostly
    +-background and shrinks 10x; noisy float data barely shrinks and costs ~0.5 s a frame).
    The zip entries carry a fixed date, so equal arrays give byte-identical files (with any
    number of deflating threads: mpmfx.io.npz).
    """
    path = Path(path)
    squeeze = set(arrays) if compress is True else set(compress or ())

    def readable(tmp: Path) -> bool:  # the central directory is written last: a cut file has none
        with zipfile.ZipFile(tmp) as zf:
            return len(zf.namelist()) == len(arrays) + 1

    entries = [
        (name, np.asanyarray(value), name in squeeze)
        for name, value in {"_format": np.int32(FRAME_FORMAT), **arrays}.items()
    ]
    with atomic_path(path, verify=readable, checksum=True) as tmp, open(tmp, "wb") as f:
        write_npz(f, entries)  # big entries deflated on several threads (mpmfx.io.npz)
    return path


def read_arrays(path: str | Path, names: Collection[str] | None = None, alloc=None) -> dict[str, np.ndarray]:
    """The arrays of a frame file (those in `names`, None: all), big ones inflated on several
    threads at once (mpmfx.io.npz; alloc: read_npz's, where the arrays' bytes go)."""
    data = read_npz(path, None if names is None else {"_format", *names}, alloc=alloc)
    out = {k: a for k, a in data.items() if k != "_format"}
    fmt = int(data["_format"]) if "_format" in data else -1
    if fmt not in READS:
        raise ValueError(
            f"{path}: frame format {fmt}, this mpmfx reads {', '.join(map(str, READS))}: "
            f"re-run the stage (mpmfx run SHOT --force STAGE)"
        )
    return out


# ---------------------------------------------------------------------------------------------
# Typed records: the only code that knows how a stage's frame file is laid out.


@dataclass
class SeedParticles:
    """The voxelise stage's particles, world units: x (n,3) float64 m, v (n,3) float64 m/s,
    volume (n,) float64 m^3, body (n,) int32 (index into shot.bodies: objects, then emitters);
    birth (n,) float64 s from frame_start at which the particle enters (late objects, emitters),
    or None: every particle is there from the start."""

    x: np.ndarray
    v: np.ndarray
    volume: np.ndarray
    body: np.ndarray
    birth: np.ndarray | None = None

    FILE = "particles.npz"

    def write(self, folder: str | Path) -> Path:
        return write_arrays(Path(folder) / self.FILE, {k: a for k, a in vars(self).items() if a is not None})

    @classmethod
    def read(cls, folder: str | Path) -> SeedParticles:
        return cls(**read_arrays(Path(folder) / cls.FILE))


@dataclass
class ParticleFrame:
    """One simulated frame, world units: x, v (n,3) float32 m, m/s; id, material, body (n,)
    int32 (id: the particle's index among the voxelise stage's particles, the same in every
    frame; a frame holds the particles in the shot, not the removed ones nor those that enter
    later, before they do; material: index into the simulate stage's materials; body: index
    into shot.bodies); Jp (snow/sand plastic volume ratio) and J (water
    volume ratio) (n,) float32 where a material has them, else None.

    On disk, 28 bytes a particle where every material has J and Jp: an id that counts 0..n-1 (no
    particle removed or still to enter) is left out and rebuilt on read."""

    x: np.ndarray
    v: np.ndarray
    id: np.ndarray
    material: np.ndarray
    body: np.ndarray
    Jp: np.ndarray | None = None
    J: np.ndarray | None = None

    EXT = "npz"  # frames/NNNN.npz in the simulate stage's entry
    # material and body indices come in long runs and Jp is mostly exactly 1 (snow) or 0 (sand):
    # they deflate 10-100x, fast. Positions, velocities and J (det F, or water's J) are noisy
    # floats, and ids count up: deflate shrinks them 10-35 % (zlib at 35-50 MB/s; ISA-L,
    # the writer's, at 340-550 MB/s on a settled pile's x and v, 1.05-1.1x): not worth a 10M
    # frame's ~0.6 CPU-s beside the solver
    _DEFLATE = ("material", "body", "Jp")

    def write(self, path: str | Path) -> Path:
        arrays = self.arrays()
        if _counts_up(self.id):
            del arrays["id"]
        return write_arrays(path, arrays, compress=[k for k in self._DEFLATE if getattr(self, k) is not None])

    @classmethod
    def read(cls, path: str | Path, fields: Collection[str] | None = None, alloc=None) -> ParticleFrame:
        """fields: the arrays to read (None: all); the others are None (the surfacer needs x, v
        and body, not the materials' state). alloc: where the arrays' bytes go (read_arrays)."""
        arrays = read_arrays(path, None if fields is None else {*fields, "x"}, alloc)  # (x: the count)
        if "id" not in arrays and (fields is None or "id" in fields):
            arrays["id"] = np.arange(len(arrays["x"]), dtype=np.int32)
        unread = dict.fromkeys(f.name for f in dataclasses.fields(cls))
        return cls(**unread | arrays)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: a for k, a in vars(self).items() if a is not None}


def _counts_up(ids: np.ndarray) -> bool:
    """ids == 0, 1, ..., n-1 (the whole voxelised set in order)."""
    n = len(ids)
    return n == 0 or (int(ids[0]) == 0 and int(ids[-1]) == n - 1 and bool(np.all(np.diff(ids) == 1)))


@dataclass
class GroupSurface:
    """One surface group's mesh and sparse level set, world units.

    vertices, normals (m,3) float32 m / unit; velocities (m,3) float32 m/s (float16 as read from a
    frame file: 1e-3 relative is below what a shading normal or motion blur shows); faces (k,3) int32;
    block_ijk (b,3) int64 leaf origins in voxels; blocks (b,8,8,8) float32 signed distance (m);
    inside_ijk (c,3) int64 leaves wholly inside; voxel_size, background (m); vel_blocks
    (b,8,8,8,3) float16 m/s; density_blocks (b,8,8,8) float16 fog density 0..1 (or None).
    The leaves are None in a shot that exports no VDB: they are its only reader, and three
    quarters of a frame's bytes."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    velocities: np.ndarray
    voxel_size: float
    background: float
    block_ijk: np.ndarray | None = None  # the leaves: None where no stage reads them (no VDB export)
    blocks: np.ndarray | None = None
    inside_ijk: np.ndarray | None = None
    vel_blocks: np.ndarray | None = None
    density_blocks: np.ndarray | None = None


@dataclass
class SurfaceFrame:
    """One frame of the surface stage: {group name: GroupSurface}, in the stage's group order."""

    groups: dict[str, GroupSurface]

    EXT = "npz"  # frames/NNNN.npz in the surface stage's entry
    # On jelly_splash the level set is mostly +-background and the velocity
    # leaves half exact zeros (both ~2.3-2.5x), the fog mostly exact 0 and 1, faces index runs (~3.5x),
    # vertices sit on lattice edges (~1.9x); normals and mesh velocities barely shrink (1.1x): stored
    _DEFLATE = ("blocks", "density_blocks", "vel_blocks", "faces", "vertices")
    _HALF = ("normals", "velocities")  # 25 bytes a vertex on disk, not 37

    def write(self, path: str | Path) -> Path:
        out: dict[str, np.ndarray] = {"groups": np.asarray(list(self.groups))}
        for g, s in self.groups.items():
            out |= {
                f"{g}.{k}": (
                    np.float64(a)
                    if k in ("voxel_size", "background")
                    else a.astype(np.float16, copy=False)
                    if k in self._HALF
                    else a
                )
                for k, a in vars(s).items()
                if a is not None
            }
        return write_arrays(path, out, compress=[f"{g}.{k}" for g in self.groups for k in self._DEFLATE])

    @classmethod
    def read(cls, path: str | Path, fields: Collection[str] | None = None) -> SurfaceFrame:
        """fields: the GroupSurface fields to read (None: all); the others are None (the export
        without VDB grids needs the mesh, not the leaves)."""
        names = None
        if fields is not None:
            names = ["groups"] + [f"{g}.{k}" for g in read_arrays(path, ["groups"])["groups"] for k in fields]
        data = read_arrays(path, names)
        unread = dict.fromkeys(f.name for f in dataclasses.fields(GroupSurface))
        return cls(
            {
                str(g): GroupSurface(
                    **unread | {k.split(".", 1)[1]: a for k, a in data.items() if k.startswith(f"{g}.")}
                )
                for g in data["groups"]
            }
        )
