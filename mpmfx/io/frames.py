"""Per-frame array files: a versioned `.npz` of named arrays, written atomically.

Used for particle frames (simulate), surfaces (surface) and checkpoints. `np.savez` output is
byte-for-byte deterministic for the same arrays, which the cache tests rely on.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from mpmfx.cache import atomic_path

FRAME_FORMAT = 1


def write_arrays(path: str | Path, arrays: dict[str, np.ndarray], *, compress: bool = False) -> Path:
    """Write `arrays` to `path` (.npz) so that the file is complete or absent.

    compress: zlib (deterministic too); worth it for level sets, which are mostly +-background.
    """
    path = Path(path)
    save = np.savez_compressed if compress else np.savez
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            save(f, _format=np.int32(FRAME_FORMAT), **arrays)
    return path


def read_arrays(path: str | Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        out = {k: data[k] for k in data.files if k != "_format"}
        fmt = int(data["_format"]) if "_format" in data.files else -1
    if fmt != FRAME_FORMAT:
        raise ValueError(f"{path}: frame format {fmt}, this mpmfx reads {FRAME_FORMAT}: "
                         f"re-run the stage (mpmfx run SHOT --force STAGE)")
    return out
