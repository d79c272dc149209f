"""Per-frame array files: a versioned `.npz` of named arrays, written atomically.

Used for particle frames (simulate), surfaces (surface) and checkpoints. The output is
byte-for-byte deterministic for the same arrays, which the cache tests rely on.
"""
from __future__ import annotations

import io
import zipfile
from collections.abc import Collection
from pathlib import Path

import numpy as np

from mpmfx.cache import atomic_path

FRAME_FORMAT = 1


def write_arrays(path: str | Path, arrays: dict[str, np.ndarray], *,
                 compress: bool | Collection[str] = False) -> Path:
    """Write `arrays` to `path` (.npz) so that the file is complete or absent.

    compress: True, False, or the names of the arrays worth deflating (a level set is mostly
    +-background and shrinks 10x; noisy float data barely shrinks and costs ~0.5 s a frame).
    The zip entries carry a fixed date, so equal arrays give byte-identical files.
    """
    path = Path(path)
    squeeze = set(arrays) if compress is True else set(compress or ())
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w") as zf:
        for name, value in {"_format": np.int32(FRAME_FORMAT), **arrays}.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asanyarray(value), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED if name in squeeze else zipfile.ZIP_STORED
            zf.writestr(info, buf.getvalue(), compresslevel=1 if name in squeeze else None)
    return path


def read_arrays(path: str | Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        out = {k: data[k] for k in data.files if k != "_format"}
        fmt = int(data["_format"]) if "_format" in data.files else -1
    if fmt != FRAME_FORMAT:
        raise ValueError(f"{path}: frame format {fmt}, this mpmfx reads {FRAME_FORMAT}: "
                         f"re-run the stage (mpmfx run SHOT --force STAGE)")
    return out
