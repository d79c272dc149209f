"""Checksums of the cache's files: what was written is what is read and published.

Each file a stage writes through `mpmfx.cache.atomic_path(..., checksum=True)` gets its digest
computed from the temp file just before the rename and kept beside it in a hidden sidecar,
`.<name>.b2` ("<bytes> <hex digest>"). The sidecar is written before the rename, so a complete
file always has one that describes it (a kill between the two leaves a sidecar that no longer
matches an older file there: that file is then redone, never trusted). The stage's manifest
copies every digest (`Entry.write_manifest`); readers and the publish compare against them.

The digest: SHA-256 (`sha256sum`) of the bytes for a file of one PIECE or less; for a larger
file, SHA-256 over the SHA-256 digests of its PIECE-sized pieces in order, so the pieces hash on
up to MAX_THREADS threads where there are cores for them (hashlib releases the GIL). SHA-256
runs on the SHA extensions of current x86 and ARM cores: 1.38 GB/s a core on the 2-core CPU,
where blake2b-128, the digest before, ran 0.62 GB/s (a 10M-particle frame is 292 MB). Digests
recorded before (32 hex digits) are checked as they were made, with blake2b-128. Standard
library only.
"""

from __future__ import annotations

import hashlib
import os
import uuid
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ALGORITHM = "sha256, 4 MiB pieces"  # named in every manifest that records digests
LEGACY_HEX = 32  # hex digits of a blake2b-128 digest (what entries recorded before SHA-256)
PIECE = 4 << 20  # bytes hashed as one piece
MAX_THREADS = 8
# sidecar: .<name>.b2 beside the file (named for the digest it first held; kept: older entries' are found)
SUFFIX = ".b2"


class DamagedError(Exception):
    """A cache file that differs from what was written (its digest or its size), or is gone:
    the entry at `root` must redo it. Picklable (it crosses from Dask workers to the client)."""

    def __init__(self, root: str, rel: str, why: str):
        super().__init__(root, rel, why)
        self.root, self.rel, self.why = root, rel, why

    def __str__(self) -> str:
        return f"{Path(self.root) / self.rel}: {self.why}"


def _threads() -> int:
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(MAX_THREADS, cores))


def _sha256(data) -> bytes:
    return hashlib.sha256(data).digest()


def _b2(data) -> bytes:
    return hashlib.blake2b(data, digest_size=16).digest()


def digest(path: str | Path, like: str | None = None) -> str:
    """The file's digest (module docstring), hex; like: a digest recorded for it, whose kind
    this one takes (an older entry's blake2b-128)."""
    h = _b2 if like is not None and len(like) == LEGACY_HEX else _sha256
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if size <= PIECE:
            return h(f.read()).hex()
        fd, n = f.fileno(), -(-size // PIECE)
        piece = lambda i: h(os.pread(fd, PIECE, i * PIECE))  # noqa: E731
        with ThreadPoolExecutor(max_workers=min(_threads(), n), thread_name_prefix="mpmfx-digest") as pool:
            parts = list(pool.map(piece, range(n)))
    return h(b"".join(parts)).hex()


def digests(paths: list[Path], like: list[str | None] | None = None) -> list[str]:
    """digest() of each path (like: as digest's, one a path), small files on several threads at once."""
    like = like or [None] * len(paths)
    if len(paths) < 2:
        return [digest(p, w) for p, w in zip(paths, like)]
    with ThreadPoolExecutor(max_workers=min(_threads(), len(paths)), thread_name_prefix="mpmfx-digest") as pool:
        return list(pool.map(digest, paths, like))


def sidecar(path: str | Path) -> Path:
    path = Path(path)
    return path.with_name(f".{path.name}{SUFFIX}")


def record(path: str | Path, written: str | Path | None = None) -> str:
    """Write `path`'s sidecar from the bytes of `written` (the temp file about to be renamed to
    `path`; default `path` itself, for a file a child process wrote). Returns the digest."""
    src = Path(written or path)
    line = f"{src.stat().st_size} {digest(src)}"
    side = sidecar(path)
    tmp = side.with_name(f"{side.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    try:
        tmp.write_text(line)
        os.replace(tmp, side)
    finally:
        tmp.unlink(missing_ok=True)
    return line.split()[1]


def written(path: str | Path) -> tuple[int, str] | None:
    """(bytes, digest) that `path`'s sidecar recorded when it was written; None without one."""
    try:
        size, hexdigest = sidecar(path).read_text().split()
        return (int(size), hexdigest) if len(hexdigest) in (LEGACY_HEX, 64) else None
    except (OSError, ValueError):
        return None


def recorded(path: str | Path) -> str | None:
    """The digest recorded when `path` was written, or None: no sidecar, an unreadable one, or
    one of another size than the file (which then cannot be the bytes it describes)."""
    try:
        rec = written(path)
        return rec[1] if rec is not None and rec[0] == Path(path).stat().st_size else None
    except OSError:
        return None


def forget(path: str | Path) -> None:
    """Remove `path` and its sidecar."""
    Path(path).unlink(missing_ok=True)
    sidecar(path).unlink(missing_ok=True)
