"""The frame files' .npz writer (mpmfx.io.npz): what numpy and zipfile read back is what was
written, whatever the number of deflating threads, byte for byte, and past zip's 32-bit limits."""

import zipfile

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
