"""The .npz writer and reader of the frame files: big entries deflated, and inflated, on several
threads at once.

zipfile deflates one entry after another on one core with zlib, and a GPU shot's surface frame
then takes longer to write than the GPU takes to surface it. Here the deflate is Intel's ISA-L
(python-isal): at level 1 it shrinks a surface frame's vertices, faces and level set as much as
zlib's level 1 does, 3-8x faster (docs/benchmarks.md), and inflates ~1.5-2x faster. Each entry's
.npy bytes are cut into CHUNK pieces that are deflated independently on the process's shared
deflating threads (ISA-L releases the GIL). Every piece but the last ends on a full flush, so the
pieces join into one raw deflate stream, as pigz's do. The zip is then written around them.

The central directory records each deflated entry's pieces (their deflated lengths, in an
extra field of its own, PIECES_TAG, that other zip readers skip), so `read_npz` inflates an
entry's pieces on threads at once too, and reads stored entries straight into their arrays,
CHUNK pieces on threads at once. A big entry's CRC-32 is likewise summed a piece a thread and
the pieces' sums joined (crc32_combine). An entry written without the table (an older file) is
inflated as one stream on one thread.

The files are ordinary zips (np.load, zipfile and unzip read them), with zip64 records only where
a size or an offset needs them. Each entry carries the fixed date 1980-01-01, so the same arrays
give the same bytes whatever the number of threads, with one ISA-L version (pinned) on one kind of
CPU: ISA-L picks its code by the CPU's instructions at run time. Nothing compares a file's bytes
across machines: cache keys hash settings and code, and a file's digest is recorded where it is
written.
"""

from __future__ import annotations

import io
import math
import os
import re
import struct
import threading
import zipfile
from collections.abc import Callable, Collection
from concurrent.futures import ThreadPoolExecutor
from typing import BinaryIO

import numpy as np
from isal import isal_zlib

from mpmfx.threads import THREADS_ENV, cpu_threads, usable_cores

CHUNK = 4 << 20  # bytes of .npy data deflated as one piece
LEVEL = 1  # ISA-L's level (0-3): 1 shrinks as much as zlib's 1, at about the speed of its 0
MAX_THREADS = 8
_DOS_TIME, _DOS_DATE = 0, (0 << 9) | (1 << 5) | 1  # 1980-01-01 00:00
_U32 = 0xFFFFFFFF  # a 32-bit field's "see the zip64 record"
PIECES_TAG = 0x6D70  # extra field ("pm"): a deflated entry's piece size, then its pieces' deflated lengths (uint32)
ZIP64_LIMIT = _U32  # sizes and offsets from this on go in zip64 records (tests lower it)


def threads() -> int:
    """Deflating threads: half this process's cores, at most MAX_THREADS (1 = in the caller: on a
    2-core machine the cores are the surfacer's and the solver's). A Dask worker's share of the
    cores is the MPMFX_SURFACE_THREADS its cluster sets (mpmfx.stages.parallel), so many workers
    writing at once do not each start threads for every core."""
    cores = min(usable_cores(), cpu_threads()) if THREADS_ENV in os.environ else usable_cores()
    return max(1, min(MAX_THREADS, cores // 2))


_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}  # (pid, threads): the deflating threads
_POOLS_LOCK = threading.Lock()


def _write_pool(workers: int) -> ThreadPoolExecutor:
    """The process's deflating threads, shared by every write_npz at once: a stage writing four
    frames behind a GPU runs `workers` deflating threads, not four times that, and starts none
    a frame. Made again in a forked child (a pool's threads do not fork)."""
    key = (os.getpid(), workers)
    with _POOLS_LOCK:
        if key not in _POOLS:
            _POOLS[key] = ThreadPoolExecutor(workers, thread_name_prefix="mpmfx-deflate")
        return _POOLS[key]


def read_threads() -> int:
    """Inflating threads: this process's cores (its Dask worker's share), at most MAX_THREADS. A
    reader waits for its arrays, so unlike the writer it takes every core it has."""
    cores = min(usable_cores(), cpu_threads()) if THREADS_ENV in os.environ else usable_cores()
    return max(1, min(MAX_THREADS, cores))


def npy_parts(value: np.ndarray) -> tuple[bytes, memoryview]:
    """(the .npy header, the array's bytes in C order) of what np.save would write."""
    value = np.asarray(value, order="C")  # (ascontiguousarray would make a 0-d array 1-d)
    if value.dtype.hasobject:
        raise ValueError("npz entries hold plain arrays, not Python objects")
    header = _npy_header(value)
    return header, memoryview(value.reshape(-1)).cast("B")


def _npy_header(value: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, np.lib.format.header_data_from_array_1_0(value))
    return buf.getvalue()


def _pieces(header: bytes, data: memoryview) -> list:
    """The entry's bytes in CHUNK pieces (the first one holds the header)."""
    first = header + bytes(data[: max(CHUNK - len(header), 0)])
    rest = data[len(first) - len(header) :]
    return [first] + [rest[i : i + CHUNK] for i in range(0, len(rest), CHUNK)]


def _deflate(piece, last: bool) -> bytes:
    c = isal_zlib.compressobj(LEVEL, isal_zlib.DEFLATED, -15)
    return c.compress(piece) + c.flush(isal_zlib.Z_FINISH if last else isal_zlib.Z_FULL_FLUSH)


class _CRC:
    """The CRC-32 of head + data, data's whole CHUNK pieces summed by run() (on a pool's threads)
    and joined in order, the rest after them; result() as a Future's."""

    def __init__(self, run, head: bytes, data):
        whole = len(data) // CHUNK * CHUNK
        self._head, self._rest = head, data[whole:]
        self._sums = [run(isal_zlib.crc32, data[i : i + CHUNK]) for i in range(0, whole, CHUNK)]

    def pieces(self) -> list:
        return self._sums

    def result(self) -> int:
        crc = isal_zlib.crc32(self._head)
        for piece in self._sums:
            crc = _join(crc, piece.result(), CHUNK)
        return isal_zlib.crc32(self._rest, crc)


def _join(crc_a: int, crc_b: int, nbytes: int) -> int:
    """crc32(a + b) from crc32(a) and crc32(b) of an nbytes-long b."""
    return isal_zlib.crc32_combine(crc_a, crc_b, nbytes)


def write_npz(f: BinaryIO, entries: list[tuple[str, np.ndarray, bool]], *, workers: int | None = None) -> None:
    """Write entries (name without .npy, array, deflate it) as a zip to the open binary file f.
    workers: deflating threads (None: threads()), a pool the process's writes share (_write_pool)."""
    workers = threads() if workers is None else workers
    parts = [(name, *npy_parts(value), deflate) for name, value, deflate in entries]
    pool = _write_pool(workers) if workers > 1 else None
    jobs = []  # per entry: (crc, [deflated piece futures] or None)

    def run(fn, *args):
        return pool.submit(fn, *args) if pool else _Done(fn(*args))

    try:
        for _name, header, data, deflate in parts:
            pieces = _pieces(header, data) if deflate else None
            jobs.append(
                (
                    _CRC(run, header, data),
                    [run(_deflate, p, i == len(pieces) - 1) for i, p in enumerate(pieces)] if deflate else None,
                )
            )
        central, offset = [], 0
        for (name, header, data, deflate), (crc, deflated) in zip(parts, jobs):
            size = len(header) + len(data)
            body = [d.result() for d in deflated] if deflate else [header, data]
            packed = sum(len(b) for b in body)
            local = _local_header(name, crc.result(), packed, size, deflate)
            f.write(local)
            for b in body:
                f.write(b)
            pieces = [len(b) for b in body] if deflate and 1 < len(body) < 0x3FFF else None
            central.append(_central_header(name, crc.result(), packed, size, deflate, offset, pieces))
            offset += len(local) + packed
        _end(f, central, offset)
    finally:  # an error leaves no piece of this file still running on the shared threads
        for crc, deflated in jobs:
            for job in [*crc.pieces(), *(deflated or [])]:
                job.cancel() or job.exception()


class _Done:
    """A finished call's result, shaped like a Future (no pool: one thread)."""

    def __init__(self, value):
        self._value = value

    def result(self):
        return self._value

    def cancel(self) -> bool:
        return False

    def exception(self):
        return None


def _local_header(name: str, crc: int, packed: int, size: int, deflate: bool) -> bytes:
    raw = f"{name}.npy".encode()
    zip64 = packed >= ZIP64_LIMIT or size >= ZIP64_LIMIT
    extra = struct.pack("<HHQQ", 1, 16, size, packed) if zip64 else b""
    return (
        struct.pack(
            "<IHHHHHIIIHH",
            0x04034B50,
            45 if zip64 else 20,
            0,
            8 if deflate else 0,
            _DOS_TIME,
            _DOS_DATE,
            crc,
            _U32 if zip64 else packed,
            _U32 if zip64 else size,
            len(raw),
            len(extra),
        )
        + raw
        + extra
    )


def _central_header(
    name: str, crc: int, packed: int, size: int, deflate: bool, offset: int, pieces: list[int] | None
) -> bytes:
    raw = f"{name}.npy".encode()
    sizes64, offset64 = packed >= ZIP64_LIMIT or size >= ZIP64_LIMIT, offset >= ZIP64_LIMIT
    fields = ([size, packed] if sizes64 else []) + ([offset] if offset64 else [])  # zip64 carries these, in this order
    extra = struct.pack(f"<HH{len(fields)}Q", 1, 8 * len(fields), *fields) if fields else b""
    if pieces:
        extra += struct.pack(f"<HH{len(pieces) + 1}I", PIECES_TAG, 4 * len(pieces) + 4, CHUNK, *pieces)
    version = 45 if fields else 20
    return (
        struct.pack(
            "<IHHHHHHIIIHHHHHII",
            0x02014B50,
            (3 << 8) | version,
            version,
            0,
            8 if deflate else 0,
            _DOS_TIME,
            _DOS_DATE,
            crc,
            _U32 if sizes64 else packed,
            _U32 if sizes64 else size,
            len(raw),
            len(extra),
            0,
            0,
            0,
            0,
            _U32 if offset64 else offset,
        )
        + raw
        + extra
    )


def _end(f: BinaryIO, central: list[bytes], start: int) -> None:
    """The central directory at offset `start`, then (zip64 where needed) its end records."""
    for c in central:
        f.write(c)
    size, n = sum(len(c) for c in central), len(central)
    if n >= 0xFFFF or size >= ZIP64_LIMIT or start >= ZIP64_LIMIT:
        f.write(struct.pack("<IQHHIIQQQQ", 0x06064B50, 44, (3 << 8) | 45, 45, 0, 0, n, n, size, start))
        f.write(struct.pack("<IIQI", 0x07064B50, 0, start + size, 1))
        f.write(struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, 0xFFFF, 0xFFFF, _U32, _U32, 0))
    else:
        f.write(struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, n, n, size, start, 0))


def read_npz(
    path, names: Collection[str] | None = None, *, workers: int | None = None, alloc: Callable | None = None
) -> dict[str, np.ndarray]:
    """{name (without .npy): array} of the zip at `path`: the entries in `names` (None: all),
    deflated ones inflated on `workers` threads (None: read_threads()) at once. The arrays are
    writable, as np.load's. alloc(nbytes): a writable uint8 array of nbytes for an entry's bytes
    (the array is a view of it past its .npy header), such as page-locked memory a GPU copies
    from at full speed; None: numpy's. (An older file's one-stream entry ignores it.)"""
    workers = read_threads() if workers is None else workers
    with open(path, "rb") as f, zipfile.ZipFile(f) as zf:
        infos = [i for i in zf.infolist() if i.filename.endswith(".npy")]
        if names is not None:
            want = set(names)
            infos = [i for i in infos if i.filename[:-4] in want]
        if any(i.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED) for i in infos):
            with np.load(path, allow_pickle=False) as data:  # a zip not of this writer's making
                return {i.filename[:-4]: data[i.filename[:-4]] for i in infos}
        fd = f.fileno()
        spans = [(i, _data_offset(fd, i)) for i in infos]
        pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="mpmfx-inflate") if workers > 1 else None
        try:

            def run(fn, *args):
                return pool.submit(fn, *args) if pool else _Done(fn(*args))

            # every piece of every entry queued before the first wait
            jobs = [
                (
                    i,
                    _Pieces(run, fd, i, at, *pieces, alloc=alloc)
                    if (pieces := _pieces_of(i)) is not None
                    else run(_inflated, fd, i, at),
                )
                for i, at in spans
            ]
            return {i.filename[:-4]: job.result() for i, job in jobs}  # in the file's order
        finally:
            if pool:
                pool.shutdown(wait=True)


def _data_offset(fd: int, info: zipfile.ZipInfo) -> int:
    """Where the entry's bytes start: after its local header (name and extra field)."""
    head = os.pread(fd, 30, info.header_offset)
    if len(head) != 30 or head[:4] != b"PK\x03\x04":
        raise zipfile.BadZipFile(f"{info.filename}: no local header at {info.header_offset}")
    name_len, extra_len = struct.unpack("<HH", head[26:30])
    return info.header_offset + 30 + name_len + extra_len


# the header np.save writes for a plain dtype: read without numpy's parser, which evaluates it as
# Python (ast), and CPython 3.11's compiler fails at random ("AST constructor recursion depth
# mismatch") when threads compile at once: the frame readers' threads and Warp's, parsing kernels
_HEADER = re.compile(r"\{'descr': '([^']+)', 'fortran_order': (True|False), 'shape': \(([0-9, ]*)\), \}\s*")
_PARSE = threading.Lock()  # numpy's parser, for any other header, one thread at a time


def _npy(buf, name: str) -> tuple[np.dtype, tuple, bool, int]:
    """(dtype, shape, fortran order, header length) of the .npy bytes in `buf`."""
    head = io.BytesIO(bytes(buf[: min(len(buf), 1 << 16)]))
    version = np.lib.format.read_magic(head)
    after_magic = head.tell()
    size = struct.unpack("<H" if version == (1, 0) else "<I", head.read(2 if version == (1, 0) else 4))[0]
    start = head.tell()
    text = head.read(size).decode("latin1")
    if m := _HEADER.fullmatch(text):
        dtype = np.dtype(m.group(1))
        shape, fortran = tuple(int(d) for d in m.group(3).split(",") if d.strip()), m.group(2) == "True"
    else:
        head.seek(after_magic)
        read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        with _PARSE:
            shape, fortran, dtype = read(head)
    if dtype.hasobject:
        raise ValueError(f"{name}: npz entries hold plain arrays, not Python objects")
    return dtype, shape, fortran, start + size


def _array(buf, name: str) -> np.ndarray:
    """The array of the .npy bytes in the writable buffer `buf` (no copy)."""
    dtype, shape, fortran, start = _npy(buf, name)
    n = math.prod(shape)
    if len(buf) - start < n * dtype.itemsize:
        raise zipfile.BadZipFile(f"{name}: {len(buf) - start} bytes for {n} values of {dtype}")
    flat = np.frombuffer(buf, dtype, count=n, offset=start)
    return flat.reshape(shape[::-1]).T if fortran else flat.reshape(shape)


def _pieces_of(info: zipfile.ZipInfo) -> tuple[int, list[int]] | None:
    """(piece size, deflated lengths): a stored entry (CHUNK, []), read in pieces of this
    reader's choosing; a deflated one as its writer recorded them (PIECES_TAG), or None where it
    recorded none (one stream)."""
    if info.compress_type == zipfile.ZIP_STORED:
        return CHUNK, []
    extra, at = info.extra, 0
    while at + 4 <= len(extra):
        tag, n = struct.unpack_from("<HH", extra, at)
        if tag == PIECES_TAG and n % 4 == 0 and n >= 8:
            size, *lens = struct.unpack_from(f"<{n // 4}I", extra, at + 4)
            whole = size > 0 and sum(lens) == info.compress_size and len(lens) == -(-info.file_size // size)
            return (size, lens) if whole else None
        at += 4 + n
    return None


class _Pieces:
    """An entry read into its array's memory a CHUNK piece at a time by run() (a stored piece
    read straight in, a deflated one inflated into place), each piece summed for the CRC-32
    while its bytes are still in the cache; result() checks the sizes and the CRC and gives the
    array. size: bytes a piece (the last may be shorter); packed: the deflated pieces' lengths,
    or [] for a stored entry."""

    def __init__(self, run, fd: int, info: zipfile.ZipInfo, at: int, size: int, packed: list[int], alloc=None):
        self._info, self._size = info, size
        # not zeroed: every byte is written over
        self._buf = np.empty(info.file_size, np.uint8) if alloc is None else alloc(info.file_size)[: info.file_size]
        view = memoryview(self._buf)
        starts = range(0, info.file_size, size)
        if packed:
            offsets = np.concatenate([[0], np.cumsum(packed)]).tolist()
            self._jobs = [
                run(_inflate_sum, fd, view[i : i + size], at + offsets[k], packed[k], info.filename)
                for k, i in enumerate(starts)
            ]
        else:
            self._jobs = [run(_read_sum, fd, view[i : i + size], at + i) for i in starts]

    def result(self) -> np.ndarray:
        info, size, crc = self._info, self._size, 0
        for k, job in enumerate(self._jobs):
            got, piece_crc = job.result()
            piece = self._buf[k * size : (k + 1) * size]
            if got != len(piece):
                raise zipfile.BadZipFile(f"{info.filename}: {got} bytes where its piece {k} holds {len(piece)}")
            # whole pieces joined (piece_crc); a last, shorter one continues the sum before it
            crc = _join(crc, piece_crc, size) if got == size else isal_zlib.crc32(piece, crc)
        if crc != info.CRC:
            raise zipfile.BadZipFile(f"{info.filename}: CRC differs")
        return _array(self._buf, info.filename)


def _read_sum(fd: int, piece: memoryview, at: int) -> tuple[int, int]:
    """(bytes read into piece from offset `at`, their CRC-32)."""
    got = os.preadv(fd, [piece], at) if hasattr(os, "preadv") else _pread_into(fd, piece, at)
    return got, isal_zlib.crc32(piece[:got])


def _inflate_sum(fd: int, piece: memoryview, at: int, packed: int, name: str) -> tuple[int, int]:
    """_read_sum of entry `name`'s deflated piece: its `packed` bytes at `at` inflated into piece."""
    try:  # (ISA-L releases the GIL)
        raw = isal_zlib.decompressobj(-15).decompress(os.pread(fd, packed, at), len(piece) + 1)
    except isal_zlib.error as exc:
        raise zipfile.BadZipFile(f"{name}: a deflated piece does not inflate ({exc})") from None
    if len(raw) == len(piece):
        piece[:] = raw
    return len(raw), isal_zlib.crc32(raw)


def _pread_into(fd: int, buf: memoryview, at: int) -> int:
    data = os.pread(fd, len(buf), at)
    buf[: len(data)] = data
    return len(data)


def _inflated(fd: int, info: zipfile.ZipInfo, at: int) -> np.ndarray:
    try:
        raw = bytearray(isal_zlib.decompressobj(-15).decompress(os.pread(fd, info.compress_size, at)))
    except isal_zlib.error as exc:
        raise zipfile.BadZipFile(f"{info.filename}: does not inflate ({exc})") from None
    if len(raw) != info.file_size or isal_zlib.crc32(raw) != info.CRC:
        raise zipfile.BadZipFile(f"{info.filename}: inflated to {len(raw)} bytes or CRC differs")
    return _array(raw, info.filename)
