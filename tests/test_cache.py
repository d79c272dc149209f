"""Cache keys, atomic writes and the lock."""

import os

import pytest

from mpmfx.cache import Cache, Entry, atomic_path, stage_key


def test_key_is_canonical_and_sensitive():
    a = stage_key("surface", 1, {"r": 1.0, "s": 2}, {"simulate": "abc"}, {})
    assert a == stage_key("surface", 1, {"s": 2, "r": 1.0}, {"simulate": "abc"}, {})  # key order is irrelevant
    assert a != stage_key("surface", 2, {"r": 1.0, "s": 2}, {"simulate": "abc"}, {})  # format version
    assert a != stage_key("surface", 1, {"r": 1.5, "s": 2}, {"simulate": "abc"}, {})  # parameter
    assert a != stage_key("surface", 1, {"r": 1.0, "s": 2}, {"simulate": "abd"}, {})  # upstream


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "frames" / "0001.npz"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half a frame")
            raise RuntimeError("killed")
    assert not target.exists() and list(target.parent.iterdir()) == []


def test_entry_complete_only_with_manifest(tmp_path):
    e = Cache(tmp_path, "shot").entry("simulate", 1, {"a": 1}, {}, {})
    with atomic_path(e.frame_path(1, "npz")) as tmp:
        tmp.write_bytes(b"x")
    assert e.done_frames("npz") == [1] and not e.complete([1])
    e.write_manifest(frames=[1], timings={})
    assert e.complete([1]) and not e.complete([1, 2])


def test_code_hash_tracks_the_named_sources():
    from mpmfx.cache import code_hash

    assert code_hash(["mpmfx.mpm"]) == code_hash(("mpmfx.mpm",))  # stable
    assert code_hash(["mpmfx.mpm"]) != code_hash(["mpmfx.surface"])
    assert code_hash(["mpmfx.surface.params"]) != code_hash(["mpmfx.surface"])  # a module is not its package
    with pytest.raises(ValueError, match="mpmfx.surface.parms"):
        code_hash(["mpmfx.surface.parms"])  # a typo in a stage's CODE fails loudly, never hashes nothing


_KEYS = """
import json, sys
import mpmfx
print(json.dumps({k: e.key for k, e in mpmfx.load_shot(sys.argv[1]).entries().items()}))
"""


def test_keys_hash_exactly_the_code_each_stage_declares(tmp_path):
    """A benchmark edit invalidates no cache entry; an edit to code that export uses does."""
    import json
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    from tests.conftest import write_tiny_shot

    repo = Path(__file__).resolve().parents[1]
    copy = tmp_path / "src"
    shutil.copytree(repo / "mpmfx", copy / "mpmfx", ignore=shutil.ignore_patterns("__pycache__"))
    shot = write_tiny_shot(tmp_path)

    def keys() -> dict[str, str]:
        env = {**os.environ, "PYTHONPATH": str(copy)}
        out = subprocess.run(
            [sys.executable, "-c", _KEYS, str(shot)], env=env, cwd=tmp_path, capture_output=True, text=True, check=True
        ).stdout
        return json.loads(out)

    before = keys()
    for bench_file in (copy / "mpmfx" / "bench").glob("*.py"):
        bench_file.write_text(bench_file.read_text() + "\n# edited\n")
    (copy / "mpmfx" / "cli.py").write_text((copy / "mpmfx" / "cli.py").read_text() + "\n# edited\n")
    assert keys() == before
    params = copy / "mpmfx" / "surface" / "params.py"
    params.write_text(params.read_text() + "\n# edited\n")
    after = keys()
    assert after["voxelise"] == before["voxelise"] and after["simulate"] == before["simulate"]
    assert after["surface"] != before["surface"] and after["export"] != before["export"]


def test_the_lock_never_writes_through_a_link(tmp_path):
    from mpmfx.cache import PathError

    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    shot_dir = tmp_path / "cache" / "shot"
    shot_dir.mkdir(parents=True)
    os.symlink(victim, shot_dir / ".lock")
    with pytest.raises(PathError, match="link"):
        with Cache(tmp_path / "cache", "shot").lock():
            pass
    assert victim.read_text() == "precious"
    (shot_dir / ".lock").unlink()
    (shot_dir / ".lock").mkdir()  # not a regular file either
    with pytest.raises(PathError, match="regular file"):
        with Cache(tmp_path / "cache", "shot").lock():
            pass


def test_a_shot_folder_that_is_a_link_is_refused(tmp_path):
    from mpmfx.cache import PathError

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "cache").mkdir()
    os.symlink(elsewhere, tmp_path / "cache" / "shot")
    with pytest.raises(PathError, match="symbolic link"):
        with Cache(tmp_path / "cache", "shot").lock():
            pass
    assert list(elsewhere.iterdir()) == []


@pytest.mark.parametrize(
    "text",
    ['{"files": []}', '{"frames": null}', "[1, 2]", "not json", '{"schema": 1, "frames": [1], "files": {"a": "x"}}'],
)
def test_a_manifest_of_the_wrong_shape_makes_the_entry_partial_not_a_crash(tmp_path, text):
    e = Cache(tmp_path, "shot").entry("simulate", 1, {"a": 1}, {}, {})
    with atomic_path(e.frame_path(1, "npz")) as tmp:
        tmp.write_bytes(b"x")
    e.write_manifest(frames=[1], timings={})
    assert e.complete([1])
    e.manifest_path.write_text(text)
    assert e.manifest() is None and not e.complete([1]) and e.damaged() == []
    assert e.done_frames("npz") == [1]  # the complete frame stays: a run resumes, then rewrites the manifest


def test_a_digest_is_sha256sum_for_one_piece_and_the_same_on_any_number_of_threads(tmp_path, monkeypatch):
    import hashlib

    from mpmfx import checksum

    path = tmp_path / "f.bin"
    path.write_bytes(os.urandom(10_000))
    assert checksum.digest(path) == hashlib.sha256(path.read_bytes()).hexdigest()  # sha256sum
    monkeypatch.setattr(checksum, "PIECE", 1000)  # ten pieces
    one = checksum.digest(path)
    monkeypatch.setattr(checksum, "MAX_THREADS", 1)
    assert checksum.digest(path) == one
    data = bytearray(path.read_bytes())
    data[5555] ^= 1
    path.write_bytes(bytes(data))
    assert checksum.digest(path) != one


def test_a_written_file_is_verified_against_what_was_written(tmp_path):
    import pickle

    from mpmfx import checksum
    from mpmfx.cache import DamagedError

    e = Cache(tmp_path, "shot").entry("surface", 1, {"a": 1}, {}, {})
    with atomic_path(e.frame_path(1, "npz"), checksum=True) as tmp:
        tmp.write_bytes(b"a frame")
    e.write_manifest(frames=[1], timings={})
    man = e.manifest()
    assert man["digests"] == {"frames/0001.npz": checksum.digest(e.frame_path(1, "npz"))}
    assert e.verified(e.frame_path(1, "npz")) and e.verify() == ([], [])
    e.frame_path(1, "npz").write_bytes(b"a frAme")  # same size: sizes alone trust it
    assert e.complete([1])
    with pytest.raises(DamagedError) as caught:
        e.verified(e.frame_path(1, "npz"))
    again = pickle.loads(pickle.dumps(caught.value))  # as it crosses from a Dask worker
    assert (again.root, again.rel) == (str(e.root), "frames/0001.npz") and "checksum" in str(again)
    assert e.verify() == (["frames/0001.npz"], [])
    assert e.mark_damaged(["frames/0001.npz"]) and not e.complete([1]) and e.damaged() == ["frames/0001.npz"]
    checksum.sidecar(e.frame_path(1, "npz")).unlink()  # the manifest's copy still knows it
    assert e.verify()[0] == ["frames/0001.npz"]


def test_an_older_entrys_blake2b_digests_still_verify_and_still_catch_a_change(tmp_path):
    """Entries written before the digest was SHA-256 recorded blake2b-128 (32 hex digits) in
    their sidecars and manifests: they are checked with blake2b, not redone, and a changed byte
    is still found."""
    import hashlib

    from mpmfx import checksum

    e = Entry(tmp_path / "e", "surface", "k", {})
    path = e.frame_path(1, "npz")
    path.parent.mkdir(parents=True)
    path.write_bytes(os.urandom(3 * checksum.PIECE + 5))
    pieces = [
        hashlib.blake2b(path.read_bytes()[i : i + checksum.PIECE], digest_size=16).digest()
        for i in range(0, path.stat().st_size, checksum.PIECE)
    ]
    old = hashlib.blake2b(b"".join(pieces), digest_size=16).hexdigest()
    checksum.sidecar(path).write_text(f"{path.stat().st_size} {old}")
    assert e.verified(path) == path and e.verify(["frames/0001.npz"]) == ([], [])
    data = bytearray(path.read_bytes())
    data[checksum.PIECE + 7] ^= 1
    path.write_bytes(bytes(data))
    assert e.verify(["frames/0001.npz"])[0] == ["frames/0001.npz"]
    with pytest.raises(checksum.DamagedError, match="differ"):
        e.verified(path)
