"""The one place that builds stage keys and paths, writes files atomically and keeps manifests.

Layout (docs/architecture.md, "The cache and its keys")::

    <root>/<shot>/<stage>/<stage>-<key12>/
        manifest.json      written last: schema version, key inputs, frames, timings, QA,
                           each file's size and digest
        frames/NNNN.*      one file per frame, written to a temp name and renamed
        frames/.NNNN.*.b2  its digest, recorded as it was written (`mpmfx.checksum`)
        checkpoints/       full solver state every K frames (exact resume)

A stage key is the sha256 of canonical JSON of {stage, stage format version, the stage's own
parameters, upstream keys, input file hashes and the hash of the code modules the stage
declares (`code_hash`)}. A frame file exists only when it is complete
(temp name + os.replace), so a killed run leaves complete frames or none; the manifest is written
only when a run finishes, so an entry without one is "partial" and resumes. Sizes say whether
an entry is complete (`complete`, fast); digests say whether a file holds what was written
(`verified` where a stage reads it, `verify` before a publish and for `status --verify`).
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import fcntl
import hashlib
import json
import os
import shutil
import socket
import stat
import sys
import time
import uuid
import zipfile
import zlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

from mpmfx import checksum as sums
from mpmfx.checksum import DamagedError
from mpmfx.diskspace import diagnosed, named

MANIFEST_SCHEMA = 1
# What a reader may meet in a cache file changed after it was written, when no digest says so
# (an entry written before digests were recorded): the file is then redone, like a damaged one.
UNREADABLE = (zipfile.BadZipFile, zlib.error, EOFError)


class BusyError(RuntimeError):
    """Another run holds the shot's lock (exit code 1); the message names it."""


class PathError(ValueError):
    """A path the project would write or delete lies outside its root (exit code 2)."""


def child(root: str | Path, *parts: str, what: str = "shot.name") -> Path:
    """`root / parts...`, refused unless it resolves strictly inside `root`: a shot named `..`
    or `.` must never turn the cache or renders root itself (or its parent) into a target."""
    root = Path(root)
    path = root.joinpath(*parts)
    base = root.resolve()
    real = base.joinpath(*parts)  # the last part is not followed: it may be a link we replace
    if any(p in ("", ".", "..") or "/" in p or os.sep in p for p in parts) or base not in real.parents:
        raise PathError(
            f"{what} {'/'.join(parts)!r}: resolves to {real}, outside {base}; "
            f"use letters, digits, '_', '-' and '.', not starting with '.'"
        )
    return path


def canonical_json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def file_hash(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def code_hash(modules: list[str] | tuple[str, ...]) -> str:
    """sha256 over the sources of exactly `modules`: dotted names inside mpmfx, each a module
    (`mpmfx.surface.params`) or a package (`mpmfx.mpm`: every .py under it). A stage declares
    the modules its output depends on, so a cache made by other code is stale and an edit
    elsewhere (a benchmark, the CLI) invalidates nothing. Nothing is imported."""
    package = Path(__file__).parent
    h = hashlib.sha256()
    for name in sorted(set(modules)):
        top, *rel = name.split(".")
        path = package.joinpath(*rel)
        if top != package.name or not (path.is_dir() or path.with_suffix(".py").is_file()):
            raise ValueError(f"code_hash: {name!r} is no module or package of {package.name}")
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path.with_suffix(".py")]
        for p in files:
            h.update(p.relative_to(package).as_posix().encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


def stage_key(stage: str, version: int, params: dict, upstream: dict[str, str], inputs: dict[str, str]) -> str:
    """sha256 over what determines a stage's output. `inputs`: name -> file hash."""
    payload = {"stage": stage, "version": version, "params": params, "upstream": upstream, "inputs": inputs}
    return hashlib.sha256(canonical_json(payload).encode()).hexdigest()


class WriteError(OSError):
    """A writer returned without error but left an incomplete or unreadable file (a full disk:
    some C++ writers, pyopenvdb's among them, report nothing)."""


@contextlib.contextmanager
def atomic_path(
    path: str | Path, *, verify: Callable[[Path], object] | None = None, checksum: bool = False
) -> Iterator[Path]:
    """Yield a fresh temp path beside `path` with the same suffix (writers such as USD pick the
    format from it); rename it over `path` on success, delete it on failure, so `path` is
    complete or untouched. Before the rename the temp file must exist, be non-empty and pass
    `verify(tmp)` (which raises or returns False for a bad file): else WriteError.
    checksum: a cache file: its digest is recorded beside it before the rename
    (`mpmfx.checksum`), for the manifest and every later read.
    The writer creates the temp file itself, so it gets the usual (umask) permissions that a
    farm user reading the cache needs."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp_path = path.with_name(f".{path.stem}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp{path.suffix}")
    try:
        yield tmp_path
        _verify(tmp_path, path, verify)
        if checksum:
            sums.record(path, tmp_path)
        os.replace(tmp_path, path)
    except Exception as exc:
        # Said as the destination and the cause (a full disk, a folder not writable) while the
        # partial temp file still holds the space it got: see mpmfx.diskspace.
        if (said := diagnosed(exc, path, tmp_path)) is None:
            raise
        raise said from exc
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _verify(tmp: Path, path: Path, verify: Callable[[Path], object] | None) -> None:
    try:
        ok = tmp.stat().st_size > 0 and (verify is None or verify(tmp) is not False)
    except Exception as exc:  # noqa: BLE001 - any failure to read it back means a bad file
        # the reader's own text can be huge (pyopenvdb echoed a cut file's bytes): one short line
        ok, why = False, f" ({type(exc).__name__}: {' '.join(str(exc)[:400].split())[:160]})"
    else:
        why = ""
    if not ok:
        raise WriteError(
            errno.EIO,
            f"the written file is incomplete or unreadable{why}; is the disk full? "
            f"free space (or point --cache / $MPMFX_CACHE at a larger disk) and run again",
            str(path),
        )


def write_json(path: str | Path, data: Any) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=True, default=str))


TEMP_GLOB = ".*.tmp*"  # the names atomic_path (and the renderers) write to before the rename


def remove_temps(folder: Path) -> list[Path]:
    """Delete the temp files under `folder` (left by a killed writer); returns them. Only call it
    when nothing writes there: under the shot's lock, or after a stage's tasks have finished."""
    if not folder.is_dir():
        return []
    gone = [p for p in folder.rglob(TEMP_GLOB) if p.is_file()]
    for p in gone:
        p.unlink(missing_ok=True)
    return gone


@dataclass
class Entry:
    """One stage's cache entry: a folder named by its key."""

    root: Path
    stage: str
    key: str
    key_inputs: dict

    @property
    def manifest_path(self) -> Path:
        return self.root / "manifest.json"

    @property
    def frames_dir(self) -> Path:
        return self.root / "frames"

    def frame_path(self, frame: int, ext: str) -> Path:
        return self.frames_dir / f"{frame:04d}.{ext}"

    def manifest(self) -> dict | None:
        """The manifest, or None when it is missing, unreadable or not of the shape this code
        writes (a hand-edited or foreign one): the entry then counts as partial and is redone."""
        return read_manifest(self.root)

    def done_frames(self, ext: str) -> list[int]:
        """Frames whose file is complete (temp files never match: they start with '.')."""
        if not self.frames_dir.is_dir():
            return []
        return sorted(int(p.stem) for p in self.frames_dir.glob(f"[0-9]*.{ext}"))

    def complete(self, frames: list[int] | None = None) -> bool:
        """True when a manifest exists, covers `frames` (all of its own frames if None), lists a
        file for each of those frames, and every file it lists is still there with its size (a
        lost or truncated file makes it partial; sizes only: `verify` reads the bytes)."""
        man = self.manifest()
        if man is None or man.get("schema") != MANIFEST_SCHEMA:
            return False
        want = set(man["frames"] if frames is None else frames)
        if not want <= set(man["frames"]):
            return False
        listed = {int(Path(rel).stem) for rel in man["files"] if rel.startswith("frames/") and Path(rel).stem.isdigit()}
        if not want <= listed:  # a frame it claims but no longer lists a file for (a hand edit)
            return False
        return not self.damaged(man)

    def damaged(self, man: dict | None = None) -> list[str]:
        """Files the manifest lists that are missing or changed size since it was written, and
        those a check found changed (`mark_damaged`)."""
        man = man or self.manifest() or {}
        bad = [rel for rel in man.get("damaged", []) if not rel.startswith("checkpoints/")]  # (frames intact)
        for rel, size in man.get("files", {}).items():
            try:
                if (self.root / rel).stat().st_size != size and rel not in bad:
                    bad.append(rel)
            except OSError:
                if rel not in bad:
                    bad.append(rel)
        return bad

    def files(self) -> dict[str, int]:
        """Every output file of the entry -> bytes (not the manifest, hidden files (temp files,
        sidecars), checkpoints, QA)."""
        out = {}
        for p in sorted(self.root.rglob("*")):
            rel = p.relative_to(self.root)
            if (
                p.is_file()
                and not p.name.startswith(".")
                and rel.parts[0] not in ("checkpoints", "qa")
                and p != self.manifest_path
            ):
                out[rel.as_posix()] = p.stat().st_size
        return out

    def checkpoints(self) -> dict[str, int]:
        """The simulation's checkpoints/NNNN.npz -> bytes."""
        folder = self.root / "checkpoints"
        return {f"checkpoints/{p.name}": p.stat().st_size for p in sorted(folder.glob("[0-9]*.npz"))}

    def write_manifest(self, *, frames: list[int], timings: dict, qa: dict | None = None, extra: dict | None = None):
        files, ckpts = self.files(), self.checkpoints()
        write_json(
            self.manifest_path,
            {
                "schema": MANIFEST_SCHEMA,
                "stage": self.stage,
                "key": self.key,
                "key_inputs": self.key_inputs,
                "frames": sorted(frames),
                "timings": timings,
                "qa": qa or {},
                "written": time.time(),
                "files": files,
                "bytes": sum(files.values()),
                "checkpoints": ckpts,
                "checksum": sums.ALGORITHM,
                "digests": self._digests([*files, *ckpts]),
                **(extra or {}),
            },
        )

    def _digests(self, rels: list[str]) -> dict[str, str]:
        """rel -> digest: the one recorded when the file was written, else (a file a child
        process wrote, or one from before digests were recorded) the file's bytes now."""
        out = {rel: sums.recorded(self.root / rel) for rel in rels}
        todo = [rel for rel, d in out.items() if d is None]
        out.update(zip(todo, sums.digests([self.root / rel for rel in todo])))
        return out

    def expected(self, rel: str, man: dict | None = None) -> str | None:
        """The digest `rel` had when written: its sidecar's, else the manifest's; None when
        neither knows it (an entry written before digests were recorded: sizes only)."""
        return sums.recorded(self.root / rel) or ((man or self.manifest() or {}).get("digests") or {}).get(rel)

    def verify(self, rels: list[str] | None = None) -> tuple[list[str], list[str]]:
        """(damaged, unverified): of `rels` (default: every file and checkpoint of the entry),
        those whose bytes or size differ from what was written, and those with no digest.
        Reads every byte of them (several files at once)."""
        man = self.manifest() or {}
        rels = [*self.files(), *self.checkpoints()] if rels is None else rels
        want = {rel: self.expected(rel, man) for rel in rels}
        unverified = [rel for rel, d in want.items() if d is None]
        known = [rel for rel, d in want.items() if d is not None]
        bad = [rel for rel in rels if not (self.root / rel).is_file()]
        known = [rel for rel in known if rel not in bad]
        found = sums.digests([self.root / r for r in known], like=[want[r] for r in known])
        bad += [rel for rel, d in zip(known, found) if d != want[rel]]
        return sorted(bad), unverified

    def verified(self, path: str | Path) -> Path:
        """`path` (a file of this entry) once its bytes match its recorded digest; DamagedError
        when it is gone or differs, so the stage that wrote it redoes it. Reads it once (the
        reader that follows reads it again from the page cache)."""
        path = Path(path)
        rel = path.relative_to(self.root).as_posix()
        if not path.is_file():
            raise DamagedError(str(self.root), rel, "missing (deleted since it was written)")
        if (rec := sums.written(path)) and rec[0] != (size := path.stat().st_size):  # sizes first: no read
            raise DamagedError(str(self.root), rel, f"{size} bytes, {rec[0]} when written")
        if (want := self.expected(rel)) is not None and sums.digest(path, like=want) != want:
            raise DamagedError(str(self.root), rel, "its bytes differ from those written (checksum)")
        return path

    def read(self, path: str | Path, reader: Callable[[Path], Any]) -> Any:
        """reader(path) of a verified file of this entry; a file it cannot parse is damaged too.
        The digest is checked on a thread while the reader reads (both mostly outside the GIL:
        a 10M-face surface frame's export waits for the longer of the two, not their sum); what
        the reader returns is handed on only once the digest matched."""
        path = Path(path)
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="mpmfx-verify") as pool:
            check = pool.submit(self.verified, path)
            try:
                value = reader(path)
            except BaseException as exc:
                check.result()  # a changed or missing file says so first
                if isinstance(exc, UNREADABLE):
                    raise DamagedError(str(self.root), path.relative_to(self.root).as_posix(), str(exc)) from None
                raise
            check.result()
        return value

    def mark_damaged(self, rels: list[str]) -> bool:
        """Record in the manifest that `rels` were found changed: the entry is partial, and the
        next run deletes and redoes them (`damaged`). False when there is no manifest to mark
        (the files are then deleted here: nothing else would notice them)."""
        man = self.manifest()
        if man is None:
            for rel in rels:
                sums.forget(self.root / rel)
            return False
        known = set(man.get("damaged", []))
        write_json(self.manifest_path, {**man, "damaged": sorted(known | set(rels))})
        return True

    def invalidate(self) -> None:
        """Drop the manifest so the entry counts as partial (its complete frames stay)."""
        self.manifest_path.unlink(missing_ok=True)

    def remove(self) -> None:
        shutil.rmtree(self.root, ignore_errors=True)


def read_manifest(entry_root: Path) -> dict | None:
    """The manifest of the entry folder `entry_root` if it is readable and of the right shape."""
    try:
        man = json.loads((entry_root / "manifest.json").read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return man if valid_manifest(man) else None


def valid_manifest(man: Any) -> bool:
    """Whether `man` has the shape `Entry.write_manifest` writes, field by field."""
    if not isinstance(man, dict) or man.get("schema") != MANIFEST_SCHEMA:
        return False
    frames, files = man.get("frames"), man.get("files")
    if not isinstance(frames, list) or not all(isinstance(f, int) and not isinstance(f, bool) for f in frames):
        return False
    if not isinstance(files, dict) or not all(
        isinstance(k, str) and isinstance(v, int) and not isinstance(v, bool) and v >= 0 for k, v in files.items()
    ):
        return False
    if not all(isinstance(man.get(k), dict) for k in ("timings", "qa", "key_inputs")):
        return False
    # written by newer code (absent from older manifests: then sizes only)
    optional = {"digests": str, "checkpoints": int}
    for key, kind in optional.items():
        value = man.get(key, {})
        if not isinstance(value, dict) or not all(
            isinstance(v, kind) and not isinstance(v, bool) for v in value.values()
        ):
            return False
    damaged = man.get("damaged", [])
    return isinstance(damaged, list) and all(isinstance(r, str) for r in damaged)


class Cache:
    """Stage entries of one shot under `<root>/<shot>/`."""

    def __init__(self, root: str | Path, shot: str):
        self.root = Path(root)
        self.shot_dir = child(self.root, shot)

    def entry(self, stage: str, version: int, params: dict, upstream: dict[str, str], inputs: dict[str, str]) -> Entry:
        key = stage_key(stage, version, params, upstream, inputs)
        key_inputs = {"version": version, "params": params, "upstream": upstream, "inputs": inputs}
        return Entry(self.shot_dir / stage / f"{stage}-{key[:12]}", stage, key, key_inputs)

    @contextlib.contextmanager
    def lock(self) -> Iterator[None]:
        """Hold `<shot>/.lock` (an flock, so a killed holder never leaves it stuck) while a run
        or a clean touches the shot; a second one stops at once naming the holder (host, pid,
        command). Held by the orchestrating process only: workers it starts write freely."""
        self.shot_dir.mkdir(parents=True, exist_ok=True)
        fd = open_private(self.shot_dir / ".lock", root=self.root)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise BusyError(
                    f"another run is using {self.shot_dir}: {_holder(os.pread(fd, 4096, 0))}; "
                    f"wait for it to finish, or stop it first (a killed run keeps its complete "
                    f"frames and the next run resumes)"
                ) from None
            info = {
                "host": socket.gethostname(),
                "pid": os.getpid(),
                "argv": sys.argv,
                "since": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC"),
            }
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, json.dumps(info).encode(), 0)
            except OSError as exc:  # a full disk: said as the lock file (os.pwrite names none)
                raise named(exc, self.shot_dir / ".lock") from exc
            yield
        finally:
            os.close(fd)  # releases the flock

    def remove_orphans(self) -> list[Path]:
        """Delete temp files that a killed run left. Call only while holding `lock()`: then no
        writer of this shot is alive to own them."""
        return remove_temps(self.shot_dir)

    def entries(self, stage: str) -> list[Path]:
        d = self.shot_dir / stage
        return sorted(d.glob(f"{stage}-*")) if d.is_dir() else []


def no_links(path: Path, *, root: Path) -> None:
    """Refuse `path` (PathError) unless it lies inside `root` through real folders: a symbolic
    link anywhere below the root would send a write or a delete outside it."""
    base = root.resolve()
    rel = Path(os.path.abspath(path)).relative_to(Path(os.path.abspath(root)))
    step = Path(os.path.abspath(root))
    for part in rel.parts:
        step = step / part
        if step.is_symlink():
            raise PathError(
                f"{step} is a symbolic link: mpmfx writes and deletes only its own folders; remove the link"
            )
    if base not in path.resolve().parents and path.resolve() != base:
        raise PathError(f"{path} resolves to {path.resolve()}, outside {base}")


def open_private(path: Path, *, root: Path) -> int:
    """Open (create) a small file of mpmfx's own for reading and writing, never through a link:
    a `.lock` that is a link to another file must not make a run overwrite that file."""
    no_links(path.parent, root=root)
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise PathError(f"{path} is a symbolic link, not mpmfx's lock file: remove it") from None
        if exc.errno == errno.EISDIR:
            raise PathError(f"{path} is not a regular file, so it is not mpmfx's lock file: remove it") from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise PathError(f"{path} is not a regular file, so it is not mpmfx's lock file: remove it")
    return fd


def _holder(raw: bytes) -> str:
    try:
        h = json.loads(raw.decode())
        return f"pid {h['pid']} on {h['host']} since {h['since']} ({' '.join(h['argv'])})"
    except (ValueError, KeyError, TypeError):
        return "a process that has not written its name yet"


def default_root() -> Path:
    """`$MPMFX_CACHE`, else `./cache` in the working directory."""
    return Path(os.environ.get("MPMFX_CACHE", "cache"))
