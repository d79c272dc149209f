"""Cache keys and atomic writes."""
import pytest

from mpmfx.cache import Cache, atomic_path, stage_key


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


def test_code_hash_tracks_the_package_sources():
    from mpmfx.cache import code_hash
    assert code_hash("mpmfx.mpm") == code_hash("mpmfx.mpm")  # stable
    assert code_hash("mpmfx.mpm") != code_hash("mpmfx.surface")
