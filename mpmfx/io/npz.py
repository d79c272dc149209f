"""The .npz writer and reader of the frame files: big entries deflated, and inflated, on several
threads at once.

zipfile deflates one entry after another on one core, and a GPU shot's surface frame (~330 MB
of arrays at 3.4M particles) then takes longer to write than the GPU takes to simulate and
surface it. Here each entry's .npy bytes are cut into CHUNK pieces that are deflated independently on a
thread pool (zlib releases the GIL). Every piece but the last ends on a full flush, so the pieces
join into one raw deflate stream, as pigz's do. The zip is then written around them.

`read_npz` inflates the entries a caller asks for each on a thread of its own (one stream
cannot be cut: the pieces' boundaries are not recorded), and reads stored ones straight into
their arrays.

The files are ordinary zips (np.load, zipfile and unzip read them), with zip64 records only where
a size or an offset needs them. Each entry carries the fixed date 1980-01-01, so the same arrays
give the same bytes whatever the number of threads.
"""

from __future__ import annotations

import io
import math
import os
import struct
import zipfile
import zlib
from collections.abc import Collection
from concurrent.futures import ThreadPoolExecutor
from typing import BinaryIO

import numpy as np

from mpmfx.threads import THREADS_ENV, cpu_threads, usable_cores

CHUNK = 4 << 20  # bytes of .npy data deflated as one piece
LEVEL = 1  # zlib level, as the frame files were always written (fast; the level set still shrinks ~2.5x)
MAX_THREADS = 8
_DOS_TIME, _DOS_DATE = 0, (0 << 9) | (1 << 5) | 1  # 1980-01-01 00:00
_U32 = 0xFFFFFFFF  # a 32-bit field's "see the zip64 record"
ZIP64_LIMIT = _U32  # sizes and offsets from this on go in zip64 records (tests lower it)


def threads() -> int:
    """Deflating threads: half this process's cores, at most MAX_THREADS (1 = in the caller: on a
    2-core machine the cores are the surfacer's and the solver's). A Dask worker's share of the
    cores is the MPMFX_SURFACE_THREADS its cluster sets (mpmfx.stages.parallel), so many workers
    writing at once do not each start threads for every core."""
    cores = min(usable_cores(), cpu_threads()) if THREADS_ENV in os.environ else usable_cores()
    return max(1, min(MAX_THREADS, cores // 2))


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
    c = zlib.compressobj(LEVEL, zlib.DEFLATED, -15)
    return c.compress(piece) + c.flush(zlib.Z_FINISH if last else zlib.Z_FULL_FLUSH)


def _crc(header: bytes, data: memoryview) -> int:
    return zlib.crc32(data, zlib.crc32(header))


def write_npz(f: BinaryIO, entries: list[tuple[str, np.ndarray, bool]], *, workers: int | None = None) -> None:
    """Write entries (name without .npy, array, deflate it) as a zip to the open binary file f.
    workers: deflating threads (None: threads())."""
    workers = threads() if workers is None else workers
    parts = [(name, *npy_parts(value), deflate) for name, value, deflate in entries]
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="mpmfx-deflate") if workers > 1 else None
    try:

        def run(fn, *args):
            return pool.submit(fn, *args) if pool else _Done(fn(*args))

        jobs = []  # per entry: (crc future, [deflated piece futures] or None)
        for _name, header, data, deflate in parts:
            pieces = _pieces(header, data) if deflate else None
            jobs.append(
                (
                    run(_crc, header, data),
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
            central.append(_central_header(name, crc.result(), packed, size, deflate, offset))
            offset += len(local) + packed
        _end(f, central, offset)
    finally:
        if pool:
            pool.shutdown(wait=True)


class _Done:
    """A finished call's result, shaped like a Future (no pool: one thread)."""

    def __init__(self, value):
        self._value = value

    def result(self):
        return self._value


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


def _central_header(name: str, crc: int, packed: int, size: int, deflate: bool, offset: int) -> bytes:
    raw = f"{name}.npy".encode()
    sizes64, offset64 = packed >= ZIP64_LIMIT or size >= ZIP64_LIMIT, offset >= ZIP64_LIMIT
    fields = ([size, packed] if sizes64 else []) + ([offset] if offset64 else [])  # zip64 carries these, in this order
    extra = struct.pack(f"<HH{len(fields)}Q", 1, 8 * len(fields), *fields) if fields else b""
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


def read_npz(path, names: Collection[str] | None = None, *, workers: int | None = None) -> dict[str, np.ndarray]:
    """{name (without .npy): array} of the zip at `path`: the entries in `names` (None: all),
    deflated ones inflated on `workers` threads (None: read_threads()) at once. The arrays are
    writable, as np.load's."""
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
        stored = [(i, at) for i, at in spans if i.compress_type == zipfile.ZIP_STORED]
        packed = [(i, at) for i, at in spans if i.compress_type == zipfile.ZIP_DEFLATED]
        out = {i.filename[:-4]: _stored(fd, i, at) for i, at in stored}
        inflate = lambda item: _inflated(fd, *item)  # noqa: E731
        if workers > 1 and len(packed) > 1:
            with ThreadPoolExecutor(max_workers=min(workers, len(packed)), thread_name_prefix="mpmfx-inflate") as pool:
                arrays = list(pool.map(inflate, packed))
        else:
            arrays = [inflate(item) for item in packed]
        out |= {i.filename[:-4]: a for (i, _), a in zip(packed, arrays)}
    return {i.filename[:-4]: out[i.filename[:-4]] for i in infos}  # in the file's order


def _data_offset(fd: int, info: zipfile.ZipInfo) -> int:
    """Where the entry's bytes start: after its local header (name and extra field)."""
    head = os.pread(fd, 30, info.header_offset)
    if len(head) != 30 or head[:4] != b"PK\x03\x04":
        raise zipfile.BadZipFile(f"{info.filename}: no local header at {info.header_offset}")
    name_len, extra_len = struct.unpack("<HH", head[26:30])
    return info.header_offset + 30 + name_len + extra_len


def _npy(buf, name: str) -> tuple[np.dtype, tuple, bool, int]:
    """(dtype, shape, fortran order, header length) of the .npy bytes in `buf`."""
    head = io.BytesIO(bytes(buf[: min(len(buf), 1 << 16)]))
    version = np.lib.format.read_magic(head)
    read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    shape, fortran, dtype = read(head)
    if dtype.hasobject:
        raise ValueError(f"{name}: npz entries hold plain arrays, not Python objects")
    return dtype, shape, fortran, head.tell()


def _array(buf, name: str) -> np.ndarray:
    """The array of the .npy bytes in the writable buffer `buf` (no copy)."""
    dtype, shape, fortran, start = _npy(buf, name)
    n = math.prod(shape)
    if len(buf) - start < n * dtype.itemsize:
        raise zipfile.BadZipFile(f"{name}: {len(buf) - start} bytes for {n} values of {dtype}")
    flat = np.frombuffer(buf, dtype, count=n, offset=start)
    return flat.reshape(shape[::-1]).T if fortran else flat.reshape(shape)


def _stored(fd: int, info: zipfile.ZipInfo, at: int) -> np.ndarray:
    buf = bytearray(info.file_size)
    got = os.preadv(fd, [buf], at) if hasattr(os, "preadv") else _pread_into(fd, buf, at)
    if got != info.file_size:
        raise zipfile.BadZipFile(f"{info.filename}: {got} of {info.file_size} bytes")
    if zlib.crc32(buf) != info.CRC:
        raise zipfile.BadZipFile(f"{info.filename}: CRC differs")
    return _array(buf, info.filename)


def _pread_into(fd: int, buf: bytearray, at: int) -> int:
    data = os.pread(fd, len(buf), at)
    buf[: len(data)] = data
    return len(data)


def _inflated(fd: int, info: zipfile.ZipInfo, at: int) -> np.ndarray:
    d = zlib.decompressobj(-15)
    raw = bytearray(d.decompress(os.pread(fd, info.compress_size, at)))  # zlib releases the GIL
    if len(raw) != info.file_size or zlib.crc32(raw) != info.CRC:
        raise zipfile.BadZipFile(f"{info.filename}: inflated to {len(raw)} bytes or CRC differs")
    return _array(raw, info.filename)
