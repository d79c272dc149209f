"""The frame files' .npz writer (mpmfx.io.npz): what numpy and zipfile read back is what was
written, whatever the number of deflating threads, byte for byte, and past zip's 32-bit limits."""

import zipfile
import zlib

import numpy as np
import pytest

from mpmfx.io import npz
from mpmfx.io.frames import read_arrays, write_arrays


def arrays():
    rng = np.random.default_rng(3)
    return {
        "x": rng.normal(size=(40_000, 3)).astype(np.float32),  # several pieces at the test's CHUNK
        "blocks": np.full((300, 8, 8, 8), 0.25, np.float32),
        "scalar": np.float64(2.5),
        "fortran": np.asfortranarray(rng.normal(size=(30, 7))),
        "strided": rng.integers(0, 9, (20, 3))[:, 1],
        "empty": np.zeros((0, 3), np.int32),
        "name": np.asarray(["all", "jelly"]),
    }


def check(path, expected):
    got = read_arrays(path)
    assert set(got) == set(expected)
    for k, v in expected.items():
        v = np.asarray(v)
        assert got[k].dtype == v.dtype and got[k].shape == v.shape and np.array_equal(got[k], v), k
    with zipfile.ZipFile(path) as zf:
        assert zf.testzip() is None  # every entry's CRC


def test_round_trip_and_the_same_bytes_on_any_number_of_threads(tmp_path, monkeypatch):
    monkeypatch.setattr(npz, "CHUNK", 64 << 10)
    files = []
    for workers in (1, 3):
        monkeypatch.setattr(npz, "threads", lambda w=workers: w)
        files.append(write_arrays(tmp_path / f"t{workers}.npz", arrays(), compress=["x", "blocks", "empty"]))
        check(files[-1], arrays())
    assert files[0].read_bytes() == files[1].read_bytes()
    with zipfile.ZipFile(files[0]) as zf:
        kinds = {i.filename: i.compress_type for i in zf.infolist()}
    assert kinds["x.npy"] == kinds["blocks.npy"] == zipfile.ZIP_DEFLATED and kinds["scalar.npy"] == zipfile.ZIP_STORED
    assert files[0].stat().st_size < 0.5 * sum(np.asarray(a).nbytes for a in arrays().values())  # the level set shrinks


def test_zip64_records_where_sizes_and_offsets_pass_the_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(npz, "ZIP64_LIMIT", 1000)  # as a > 4 GB frame would
    path = write_arrays(tmp_path / "big.npz", arrays(), compress=["x"])
    check(path, arrays())
    with np.load(path) as data:
        assert np.array_equal(data["blocks"], arrays()["blocks"])


def test_python_objects_are_refused(tmp_path):
    with pytest.raises(ValueError, match="plain arrays"):
        write_arrays(tmp_path / "o.npz", {"o": np.array([{}, 1], dtype=object)})
    assert not list(tmp_path.iterdir())  # nothing left behind


def test_deflating_threads_follow_the_process_share_of_the_cores(monkeypatch):
    monkeypatch.setattr(npz.os, "sched_getaffinity", lambda pid: set(range(16)), raising=False)
    monkeypatch.delenv("MPMFX_SURFACE_THREADS", raising=False)
    assert npz.threads() == 8  # half the cores, at most MAX_THREADS
    monkeypatch.setenv("MPMFX_SURFACE_THREADS", "2")  # a Dask worker's share (parallel._worker_env)
    assert npz.threads() == 1


def test_pieces_are_read_on_threads_and_every_one_is_checked(tmp_path, monkeypatch):
    """Stored and deflated entries come back in pieces read on several threads: the pieces'
    CRCs, joined, must equal the entry's (a flipped byte in any piece is caught), and a file
    whose deflated entries carry no piece table (older files) reads as one stream."""
    monkeypatch.setattr(npz, "CHUNK", 64 << 10)
    want = arrays()
    path = write_arrays(tmp_path / "p.npz", want, compress=["x", "blocks"])
    with zipfile.ZipFile(path) as zf:
        pieces = {i.filename: npz._pieces_of(i) for i in zf.infolist()}
        x_at = zf.getinfo("x.npy").header_offset  # deflated
        stored_at = zf.getinfo("fortran.npy").header_offset  # stored
    assert pieces["x.npy"][0] == npz.CHUNK and len(pieces["x.npy"][1]) == -(-want["x"].nbytes // npz.CHUNK)
    assert pieces["fortran.npy"] == (npz.CHUNK, [])
    monkeypatch.setattr(npz, "CHUNK", 48 << 10)  # a reader of another piece size reads the writer's pieces
    for workers in (1, 4):
        got = npz.read_npz(path, workers=workers)
        assert all(np.array_equal(got[k], np.asarray(v)) for k, v in want.items())
    for at in (x_at + 500 + 3 * (64 << 10) // 2, stored_at + 200):
        bad = bytearray(path.read_bytes())
        bad[at] ^= 0x10
        (tmp_path / "bad.npz").write_bytes(bad)
        with pytest.raises((zipfile.BadZipFile, zlib.error)):
            npz.read_npz(tmp_path / "bad.npz", workers=4)
    monkeypatch.setattr(npz, "PIECES_TAG", 0x7777)  # a writer that records no table, as older ones
    old = write_arrays(tmp_path / "old.npz", want, compress=["x", "blocks"])
    monkeypatch.setattr(npz, "PIECES_TAG", 0x6D70)
    with zipfile.ZipFile(old) as zf:
        assert npz._pieces_of(zf.getinfo("x.npy")) is None
    check(old, want)


@pytest.mark.parametrize("size", [0, 1, 1000, 64 << 10, (64 << 10) + 1, 5 * (64 << 10) - 3])
def test_joined_piece_crcs_equal_zlibs(size, monkeypatch):
    monkeypatch.setattr(npz, "CHUNK", 64 << 10)
    data = memoryview(np.random.default_rng(size).integers(0, 256, size, np.uint8).tobytes())
    assert npz._CRC(lambda fn, *a: npz._Done(fn(*a)), b"head", data).result() == zlib.crc32(b"head" + bytes(data))


def test_plain_headers_are_read_without_pythons_compiler(tmp_path, monkeypatch):
    """numpy evaluates a .npy header as Python (ast), and CPython 3.11's compiler fails at random
    when threads compile at once (frame readers beside Warp's kernel parsing): the headers np.save
    writes for plain dtypes are read without it; others still read, one thread at a time."""
    path = write_arrays(tmp_path / "h.npz", arrays(), compress=["x"])

    def refuse(*a, **k):
        raise AssertionError("numpy's header parser was called")

    monkeypatch.setattr(np.lib.format, "read_array_header_1_0", refuse)
    got = read_arrays(path)
    assert all(np.array_equal(got[k], np.asarray(v)) for k, v in arrays().items())
    monkeypatch.undo()
    mixed = {"rec": np.zeros(3, dtype=[("a", "<f4"), ("b", "<i8")])}
    assert read_arrays(write_arrays(tmp_path / "r.npz", mixed))["rec"].dtype == mixed["rec"].dtype


def _zlib_deflate(piece, last: bool) -> bytes:
    c = zlib.compressobj(1, zlib.DEFLATED, -15)
    return c.compress(piece) + c.flush(zlib.Z_FINISH if last else zlib.Z_FULL_FLUSH)


def test_files_deflated_by_zlib_still_read(tmp_path, monkeypatch):
    """Caches written before the frame files were deflated with ISA-L hold zlib's streams: they
    read as they did, pieces and all."""
    monkeypatch.setattr(npz, "CHUNK", 64 << 10)
    monkeypatch.setattr(npz, "_deflate", _zlib_deflate)
    old = write_arrays(tmp_path / "zlib.npz", arrays(), compress=["x", "blocks"])
    monkeypatch.undo()
    monkeypatch.setattr(npz, "CHUNK", 64 << 10)
    check(old, arrays())
    new = write_arrays(tmp_path / "isal.npz", arrays(), compress=["x", "blocks"])
    assert new.read_bytes() != old.read_bytes()  # the other deflate: the same arrays, other streams
    check(new, arrays())


def test_writes_at_once_share_one_set_of_deflating_threads(tmp_path, monkeypatch):
    """Four frames written at once (the GPU surface stage's writers) give the bytes a lone write
    gives, on the process's one pool of deflating threads, not a pool each."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    monkeypatch.setattr(npz, "CHUNK", 64 << 10)
    monkeypatch.setattr(npz, "threads", lambda: 3)
    alone = write_arrays(tmp_path / "alone.npz", arrays(), compress=["x", "blocks"]).read_bytes()
    before = threading.active_count()
    with ThreadPoolExecutor(4) as writers:
        paths = list(
            writers.map(lambda k: write_arrays(tmp_path / f"w{k}.npz", arrays(), compress=["x", "blocks"]), range(4))
        )
        assert threading.active_count() <= before + 4  # the writers; the deflating threads were already there
    assert all(p.read_bytes() == alone for p in paths)


def test_a_failed_write_leaves_no_piece_running(tmp_path, monkeypatch):
    """A write that fails midway (a full disk) cancels or finishes its pieces on the shared
    threads before it raises, and the next write is whole."""
    monkeypatch.setattr(npz, "CHUNK", 16 << 10)
    pool = npz._write_pool(2)

    class Full:
        def __init__(self):
            self.n = 0

        def write(self, b):
            self.n += len(b)
            if self.n > 50_000:
                raise OSError(28, "No space left on device")

    entries = [(k, np.asarray(v), k in ("x", "blocks")) for k, v in arrays().items()]
    with pytest.raises(OSError, match="No space"):
        npz.write_npz(Full(), entries, workers=2)
    assert pool._work_queue.empty()
    check(write_arrays(tmp_path / "after.npz", arrays(), compress=["x", "blocks"]), arrays())


def test_arrays_are_read_into_the_memory_alloc_gives(tmp_path, monkeypatch):
    """read_npz's alloc (the GPU surface stage's page-locked buffers): every entry read in pieces
    lands in the caller's memory, stored and deflated alike, with the same values."""
    monkeypatch.setattr(npz, "CHUNK", 64 << 10)
    path = write_arrays(tmp_path / "a.npz", arrays(), compress=["x", "blocks"])
    given = []

    def alloc(nbytes):
        given.append(np.empty(nbytes + 100, np.uint8))  # larger than asked, as a pool's buffer
        return given[-1]

    got = read_arrays(path, alloc=alloc)
    assert all(np.array_equal(got[k], np.asarray(v)) for k, v in arrays().items())
    for k in ("x", "blocks", "fortran"):
        assert any(np.shares_memory(got[k], g) for g in given), k
