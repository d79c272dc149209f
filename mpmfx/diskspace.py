"""A full disk or an unwritable folder, said as the path being written and the fix.

Writers fail on a full disk in many ways: Python's own files raise `OSError` ENOSPC without a
path, `shutil.copyfile` names its source, USD raises `Tf.ErrorException` after a page of its own
errors, pyopenvdb and ffmpeg report nothing or something else. `named` and `diagnosed` turn each
into one `OSError` of a known errno whose filename is the destination; the command line prints
it as one line and exits 2 (`mpmfx.cli`). Standard library only: the cache layer uses it.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

FULL = (errno.ENOSPC, errno.EDQUOT)
DENIED = (errno.EACCES, errno.EPERM, errno.EROFS)
# A folder with less free than this after a failed write counts as full: a write that ran out of
# space leaves its partial temp file, so the disk reads (nearly) 0 bytes free at that moment.
NEARLY_FULL = 1 << 20  # bytes


def _existing(path: Path) -> Path:
    """`path` or its nearest ancestor that exists (a folder a write would create is not there yet)."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path if path.is_dir() else path.parent


def free_bytes(path: str | Path) -> int:
    """Bytes an unprivileged user may still write on the file system holding `path`."""
    st = os.statvfs(_existing(Path(path)))
    return st.f_bavail * st.f_frsize


def unwritable(path: str | Path) -> int | None:
    """EROFS or EACCES when the folder `path` (or its nearest existing ancestor) takes no new
    files, else None."""
    folder = _existing(Path(path))
    if os.statvfs(folder).f_flag & os.ST_RDONLY:
        return errno.EROFS
    if not os.access(folder, os.W_OK | os.X_OK):
        return errno.EACCES
    return None


def ensure_room(path: str | Path, need: int = 0) -> None:
    """Raise `OSError` (ENOSPC, EROFS or EACCES, filename `path`) before writing `need` bytes to
    `path` when its folder cannot take them (with NEARLY_FULL to spare), so a writer that
    reports a full disk badly (USD) is never started on one."""
    if (code := unwritable(Path(path).parent)) is not None:
        raise OSError(code, os.strerror(code), str(path))
    if free_bytes(Path(path).parent) < need + NEARLY_FULL:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))


def named(exc: OSError, path: str | Path) -> OSError:
    """`exc` as an OSError of the same errno whose filename is the destination `path` (it had
    none, a temp name, or the source of a copy); `exc` itself when it already names `path`."""
    if exc.filename == str(path) and exc.filename2 is None:
        return exc
    out = OSError(exc.errno, exc.strerror or os.strerror(exc.errno or errno.EIO), str(path))
    out.__cause__ = exc
    return out


def diagnosed(exc: BaseException, path: str | Path, tmp: str | Path | None = None) -> OSError | None:
    """A writer of `path` (through the temp file `tmp`) failed with `exc`: the OSError to raise
    instead, naming `path`, when the cause is the disk (full, read-only, not writable) or `exc`
    is an OSError about the write; None (raise `exc` as it is) for anything else, such as a
    missing file the writer read."""
    if isinstance(exc, OSError) and exc.errno in FULL:
        return named(exc, path)
    if isinstance(exc, OSError) and exc.filename2 is None and _other(exc.filename, path, tmp):
        return None  # about another file (a source it read): said as it is
    if isinstance(exc, OSError) and exc.errno in DENIED:
        return named(exc, path)
    try:
        code = unwritable(Path(path).parent)
        if code is None and free_bytes(Path(path).parent) < NEARLY_FULL:
            code = errno.ENOSPC
    except OSError:
        code = None
    if code is not None:
        out = OSError(code, os.strerror(code), str(path))
        out.__cause__ = exc
        return out
    if isinstance(exc, OSError) and exc.errno is not None:
        return named(exc, path)
    return None


def _other(name, path, tmp) -> bool:
    return name is not None and str(name) not in (str(path), str(tmp))


def message(exc: OSError, *, cache_root: str | Path | None) -> str:
    """One line: what failed on which path, and the fix (free space or move the cache / the
    output folder). Complete cached frames are kept by every writer (atomic temp + rename)."""
    if not exc.filename:  # a writer outside the write layer that did not say which file
        what = "no space left on the device" if exc.errno in FULL else os.strerror(exc.errno or errno.EIO).lower()
        return (
            f"{what} (the writer named no file): free space, or point --cache (or $MPMFX_CACHE) and the "
            f"working folder (renders/, published/: here {Path.cwd()}) at a disk you may write to"
        )
    path = Path(exc.filename)
    folder = path.parent
    where = _where(path, cache_root, "on a larger disk" if exc.errno in FULL else "you may write to")
    if exc.errno in FULL:
        try:
            free = f" ({free_bytes(folder) / 2**20:.1f} MiB free there)"
        except OSError:  # (the message must not fail in its turn)
            free = ""
        return (
            f"no space left on the device writing {path}{free}: free space, or {where}; nothing cached "
            f"was damaged: run again to resume"
        )
    if exc.errno == errno.EROFS:
        return f"{folder} is on a read-only file system, so {path.name} cannot be written: {where}"
    if exc.errno in DENIED:
        return (
            f"permission denied writing {path}: make {folder} writable for this user, or {where}; "
            f"nothing cached was damaged: run again to resume"
        )
    return f"{path}: {exc.strerror}; complete frames are kept: run again to resume"


def _where(path: Path, cache_root: str | Path | None, kind: str) -> str:
    """The fix's second half: move the cache, or run from another working folder (`kind`: which)."""
    if cache_root is not None:
        root = Path(os.path.abspath(cache_root))
        if Path(os.path.abspath(path)) == root or root in Path(os.path.abspath(path)).parents:
            return f"point --cache (or $MPMFX_CACHE) at a folder {kind} (the cache is {root})"
    return (
        f"run mpmfx from a working folder {kind} (renders/ and published/ are written under the "
        f"working folder, here {Path.cwd()})"
    )
